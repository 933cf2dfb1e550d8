"""udc-render: physically based simulation of under-display camera capture."""
__version__ = "0.1.0"
