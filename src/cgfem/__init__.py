"""cgfem: contact mechanics in the Cartesian grid finite element method.

Stages, each a subpackage with a small typed interface (data flows one way):

- :mod:`cgfem.geometry` — exact NURBS boundary representation of each body;
- :mod:`cgfem.case` — case files (YAML) validated and loaded into frozen dataclasses;
- :mod:`cgfem.cli` — the ``cgfem`` command line.
"""

from cgfem.errors import InputError

__all__ = ["InputError", "__version__"]
__version__ = "0.1.0"
