"""Device emulators: the far end of each hardware link, speaking the real byte protocols."""
