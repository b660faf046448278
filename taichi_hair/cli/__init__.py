"""The ``taichi-hair`` command line (above the library: nothing in ``taichi_hair`` outside ``cli/``
imports it).  :mod:`.main` parses and dispatches; :mod:`.simulate`, :mod:`.groom` run the commands;
:mod:`.common` holds the shared options and the Taichi set-up."""

from .main import main

__all__ = ["main"]
