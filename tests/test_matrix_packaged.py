"""Every command on the package's other cases (``ks_jax/cases/``): ``command_matrix``."""

from command_matrix import matrix_test

test_every_command = matrix_test("packaged")
