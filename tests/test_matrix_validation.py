"""Every command on the validation's cases (``docs/validation/``): ``command_matrix``."""

from command_matrix import matrix_test

test_every_command = matrix_test("validation")
