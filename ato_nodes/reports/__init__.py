"""Reports of recorded runs: the verdict on every index, figures, report.md, the
interactive report.html, a journey's tables and figure, indices.json."""
