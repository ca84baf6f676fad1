"""Speed units: SI (m/s) inside, km/h only in reports, plots and the papers' figures."""

KMH = 1.0 / 3.6  # m/s per km/h: 80 * KMH is 80 km/h in m/s
MS_TO_KMH = 3.6  # km/h per m/s
