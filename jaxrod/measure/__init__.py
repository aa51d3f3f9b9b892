"""jaxrod.measure."""
