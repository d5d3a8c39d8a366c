"""procam: projector-camera compensation of interreflections in a room (Sheng et al. 2011).

Load a scene, compute what each projector must emit so that the room, bounces included, looks as
desired, and decode structured-light photographs. Arrays go in and out as NumPy arrays; shapes and
units are in each function's docstring. docs/python.md shows the paper's loop in twenty lines.
"""

from ._procam import *  # noqa: F401,F403
from ._procam import __doc__ as _native_doc  # noqa: F401
