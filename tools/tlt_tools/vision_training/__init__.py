"""Training commands of the vision models (paper §V.E), each runnable on its own with progress shown."""
