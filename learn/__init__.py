"""LPNets, G-LPNets and unstructured baselines (JAX)."""
