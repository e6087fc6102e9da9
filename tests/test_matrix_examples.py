"""Every command on the docs' examples (``docs/examples/``) and the whole cases in docs/*.md's blocks:
``command_matrix``."""

from command_matrix import matrix_test

test_every_command = matrix_test("examples")
