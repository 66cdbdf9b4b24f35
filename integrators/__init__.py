"""Ground truth (heyoka), HDF5 data sets, classical Lie-Poisson splitting, diagnostics."""
