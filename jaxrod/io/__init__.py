"""jaxrod.io."""
