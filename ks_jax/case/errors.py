"""The errors and warnings of case files: messages meant for the user, naming the case, the field, the
value and the rule."""

from __future__ import annotations


class CaseError(ValueError):
    """A user error in a case file or case dict; the message is meant for the user."""


class CaseWarning(UserWarning):
    """Something in a case that is ignored (an unknown field) or that costs precision; it is still solved."""
