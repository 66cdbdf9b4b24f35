"""Classical splitting methods built on the exact sub-flows of `system.hamiltonian_splitting()`."""
