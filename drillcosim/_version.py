"""The installed distribution's version (:mod:`importlib.metadata`; its one source is
``pyproject.toml``).

Its own module so that the packages below ``drillcosim`` read it without importing the
package root, whose attributes load the public API (no import cycle through the root).
"""

from importlib.metadata import version

__version__ = version("drillcosim")
