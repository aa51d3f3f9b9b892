"""jaxrod.studies."""
