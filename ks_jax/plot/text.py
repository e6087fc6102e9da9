"""Text in pictures that fits where it is put: a legend entry or a title holding a vehicle's or a case's full
name, wrapped to the width of its axes (or figure) as drawn, instead of running off the figure's edge."""

from __future__ import annotations


def text_width(text, size):
    """The width in points of one line of ``text`` at font ``size`` (points) in matplotlib's default font,
    as drawn (its glyphs measured, not its characters counted)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path

    return text_to_path.get_text_width_height_descent(text, FontProperties(size=size), ismath=False)[0]


def wrap_to_width(text, width, size, indent="  "):
    """``text`` broken between words into lines no wider than ``width`` points at font ``size``: a legend
    entry or a title with a vehicle's or a case's full name stays inside the axes' width instead of running
    off the figure. Line breaks already in ``text`` are kept, a name stays with its value ("t_i = 0.158"),
    and a continued line starts with ``indent`` (a legend entry's continuation then reads as part of it);
    a single word wider than ``width`` keeps a line of its own (it is not cut)."""
    lines = []
    for paragraph in text.split("\n"):
        line = ""
        for word in paragraph.replace(" = ", "\0=\0").split(" "):
            word = word.replace("\0", " ")
            longer = f"{line} {word}" if line else word
            if line and text_width(longer, size) > width:
                lines.append(line)
                line = indent + word
            else:
                line = longer
        lines.append(line)
    return "\n".join(lines)
