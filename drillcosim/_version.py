"""The distribution's version (``pyproject.toml`` carries the same string).

Its own module so that the packages below ``drillcosim`` read it without importing the
package root, whose attributes load the public API (no import cycle through the root).
"""

__version__ = "0.2.0"
