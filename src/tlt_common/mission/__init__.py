"""The mission definition (``schema``) and the CRS's persisted tower model (``tower_model``)."""
