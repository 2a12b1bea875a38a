"""Plumbing written once: the message contract, the key catalogue, config and the node runtime."""
