"""The runtime every process stands on: the node and its handles, config,
parameters, diagnostics, errors and the service entry point.

It imports only the contract and itself: no tool, no supervisor, no area.
"""
