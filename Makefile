# The README's two commands. Both set up .venv first.
.PHONY: run test schemas
run:
	scripts/run.sh
test:
	scripts/test.sh
schemas:
	.venv/bin/buddybot schemas
