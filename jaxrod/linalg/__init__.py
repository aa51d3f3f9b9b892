"""jaxrod.linalg."""
