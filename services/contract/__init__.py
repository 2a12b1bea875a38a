"""The contract: message types, the key catalogue and what is derived from them.

Pure and I/O-free. Everything else (runtime, tools, areas) reads the
contract; the contract imports nothing of BuddyBot but itself.
"""
