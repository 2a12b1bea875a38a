"""Stand-in for the component's `connected` binary sensor (validation only)."""

import esphome.config_validation as cv
from esphome.components import binary_sensor

from . import StreamServer

CONFIG_SCHEMA = cv.Schema(
    {
        cv.GenerateID("stream_server"): cv.use_id(StreamServer),
        cv.Required("connected"): binary_sensor.binary_sensor_schema(),
    }
)


async def to_code(config):
    raise NotImplementedError("stand-in for validation only: build with the real component")
