"""Step tests of an FMU (the input's effect on the output, identified as a low-order model) and the loop they
suggest for a scenario (prlpid-fmi probe, prlpid-fmi init)."""
