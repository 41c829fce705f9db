"""NumPy twins of ``tbd_taichi.kernels``: same contracts, vectorised NumPy."""
