"""Many runs of a scenario: tuning (an optimizer's candidates, in-process or through the
stack) and the study scripts' runner (variants prepared, run, scored, tabled)."""
