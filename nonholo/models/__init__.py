"""Robot models. Each model is written once as plain arithmetic over its inputs so that
the same function serves the compiled simulator (numba) and symbolic analysis (sympy)."""
