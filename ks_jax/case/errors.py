"""The errors and warnings of case files: messages meant for the user, naming the case, the field, the
value and the rule; and names from files made safe to show on a terminal (``visible``, ``visible_lines``).

A case keeps its names exactly as the file gives them (JSON carries them so); text meant for a terminal
(the panel, messages on stderr) shows them through ``visible``."""

from __future__ import annotations


class CaseError(ValueError):
    """A user error in a case file or case dict; the message is meant for the user."""


class CaseWarning(UserWarning):
    """Something in a case that is ignored (an unknown field) or that costs precision; it is still solved."""


def visible(text) -> str:
    """``text`` with every character that is not printable written as its escape (``\\x1b``, ``\\n``,
    ``\\u202e``, ``\\x00``): a name from a file reaches the terminal, where an escape sequence could retitle or
    clear it, a bidirectional override could show it reversed, and a line break would forge lines.
    Printable text is returned as it is (so ``visible(visible(t)) == visible(t)``)."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def visible_lines(text) -> str:
    """``visible`` applied line by line: a text of several lines made for the terminal (a panel) keeps
    its line breaks; anything else that is not printable in it is escaped."""
    return "\n".join(visible(line) for line in str(text).split("\n"))
