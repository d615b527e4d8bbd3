# Augmenting declarations of ccm8_cy.py, read by Cython only (plain Python ignores this file).
# LAPACK through scipy's Cython table: the very routine numba's np.linalg.eigh calls.
from scipy.linalg.cython_lapack cimport dsyevd
