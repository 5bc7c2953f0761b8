"""omavctl: learn residual models of an omnidirectional aerial vehicle from flight logs.

The library is organised by concern (see ``docs/``): ``vehicle`` (parameters),
``physics`` (rigid body, allocation, controller, effects), ``plant`` (truth
simulator), ``trajectory`` (task CSVs), ``logs`` (reading and writing flight
logs). ``cli`` only parses arguments, calls one library function and renders.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
