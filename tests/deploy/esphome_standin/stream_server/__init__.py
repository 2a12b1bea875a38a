"""Offline stand-in for the `stream_server` ESPHome component (tests only).

`esphome config` fetches external components from the network; this
directory takes the pinned component's place so the rest of
deploy/esphome/radar-esp32.yaml is validated by ESPHome itself without
network. It accepts the keys the pinned commit documents (`port`,
`buffer_size` a power of two, `uart_id`, an `id`), nothing more: a key the
real component lacks fails here too. It is never built (no `to_code`).
"""

import esphome.codegen as cg
import esphome.config_validation as cv
from esphome.components import uart
from esphome.const import CONF_BUFFER_SIZE, CONF_PORT

DEPENDENCIES = ["uart", "network"]
MULTI_CONF = True

StreamServer = cg.global_ns.class_("StreamServerComponent", cg.Component)


def power_of_two(value):
    if value <= 0 or value & (value - 1):
        raise cv.Invalid("buffer_size must be a power of two")
    return value


CONFIG_SCHEMA = (
    cv.Schema(
        {
            cv.GenerateID(): cv.declare_id(StreamServer),
            cv.Optional(CONF_PORT, default=6638): cv.port,
            cv.Optional(CONF_BUFFER_SIZE, default=128): cv.All(cv.positive_int, power_of_two),
        }
    )
    .extend(cv.COMPONENT_SCHEMA)
    .extend(uart.UART_DEVICE_SCHEMA)
)


async def to_code(config):
    raise NotImplementedError("stand-in for validation only: build with the real component")


