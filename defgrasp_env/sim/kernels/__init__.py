"""Pure Warp kernels and functions of the FEM core: they take arrays and scalars only."""
