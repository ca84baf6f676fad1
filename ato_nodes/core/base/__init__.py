"""The vocabulary every room uses: errors, parameter specs, registered kinds and the
interfaces they implement, bounded files, units, compiled kernels, the topic map."""
