"""nonholo: collaborative nonholonomic robots."""
__version__ = "0.1.0"
