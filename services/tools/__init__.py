"""Operator tools behind the CLI verbs: probing, bags, doctor, the zenoh-cli
codec and the test helpers. Built on the runtime and the contract."""
