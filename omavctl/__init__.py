"""omavctl: learn residual models of an omnidirectional aerial vehicle from flight logs.

The library is one package per pipeline stage, each importing only the ones
below it (``docs/architecture.md``): ``base`` < ``logs`` < ``vehicle`` <
``physics`` < ``sim`` < ``learn`` < ``diagnose`` < ``planning`` < ``report`` <
``cli``. ``cli`` only parses arguments, calls one library function and renders.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
