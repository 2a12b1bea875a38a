"""The simulated world: people on scripted paths that every simulated sensor sees."""
