"""jaxrod.solve."""
