"""jaxrod.model."""
