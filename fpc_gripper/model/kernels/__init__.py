"""The compiled kernels of each discretisation: energies, exact derivatives and outputs."""
