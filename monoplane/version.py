"""The package version, in a module of its own: the package's ``__init__`` names (for type
checkers) the modules its lazy attributes load, so a module inside that imports the package for
its version would close an import cycle."""

__version__ = "0.2.0"
