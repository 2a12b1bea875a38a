"""The web layer: what every web surface of the robot (the dashboard, the eye
renderer, the Foxglove bridge) shares, beside the runtime rather than in it.

Who may reach a surface and how many (`guard`), who may operate it (`auth`:
secrets, session cookies, the Foxglove token) and one page's send side
(`page_outbox`). It imports the runtime and the contract; the runtime never
imports it, so a service process without a web page does not load it
(docs/architecture.md).
"""
