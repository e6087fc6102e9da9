"""Every command on the package's reconstructions (``ks_jax/cases/fit_*``): ``command_matrix``."""

from command_matrix import matrix_test

test_every_command = matrix_test("reconstructions")
