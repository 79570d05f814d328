"""Speed benchmarks: print measured figures, never assert (timings are noisy)."""
