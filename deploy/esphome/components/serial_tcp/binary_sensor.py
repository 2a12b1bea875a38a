"""`connected`: on while a client (the radar bridge) holds the port.

Seen in the ESPHome dashboard or Home Assistant: "is the robot reading this
radar?" answered on the ESP32's side, without the robot.
"""

import esphome.codegen as cg
from esphome.components import binary_sensor
import esphome.config_validation as cv
from esphome.const import DEVICE_CLASS_CONNECTIVITY, ENTITY_CATEGORY_DIAGNOSTIC

from . import CONF_SERIAL_TCP_ID, SerialTcpServer

DEPENDENCIES = ["serial_tcp"]

CONF_CONNECTED = "connected"

CONFIG_SCHEMA = cv.Schema(
    {
        cv.GenerateID(CONF_SERIAL_TCP_ID): cv.use_id(SerialTcpServer),
        cv.Required(CONF_CONNECTED): binary_sensor.binary_sensor_schema(
            device_class=DEVICE_CLASS_CONNECTIVITY,
            entity_category=ENTITY_CATEGORY_DIAGNOSTIC,
        ),
    }
)


async def to_code(config):
    server = await cg.get_variable(config[CONF_SERIAL_TCP_ID])
    sensor = await binary_sensor.new_binary_sensor(config[CONF_CONNECTED])
    cg.add(server.set_connected_sensor(sensor))
