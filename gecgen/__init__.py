"""gecgen: Geometric and Elastic Error Compensation compiler and toolkit for large robots."""
__version__ = "0.1.0"
