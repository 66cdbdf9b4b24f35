"""Reproductions of the experiments of "Lie-Poisson Neural Networks (LPNets)"."""
