"""bwsd: control daemon with an embedded digital twin for braiding-weaving machines."""

__version__ = "0.1.0"
