"""`serial_tcp`: one UART's raw bytes served on one TCP port, both ways.

The radar bridge opens a radar on the ESP32 as `socket://HOST:PORT` and
parses the bytes exactly as from a USB adapter, so the firmware must add
nothing: no telnet negotiation, no RFC 2217, no framing. This component is
that and only that, kept in this repository so `esphome config` needs no
network and the code that carries the radars is the code reviewed here.
docs/esp32-radar.md explains the behaviour (buffers, clients, drops).
"""

import esphome.codegen as cg
from esphome.components import socket, uart
import esphome.config_validation as cv
from esphome.const import CONF_BUFFER_SIZE, CONF_ID, CONF_PORT
from esphome.core import CORE

DEPENDENCIES = ["network"]
AUTO_LOAD = ["socket"]
MULTI_CONF = True

CONF_MAX_CLIENTS = "max_clients"
CONF_SERIAL_TCP_ID = "serial_tcp_id"

# The C++ side holds at most this many clients per port (a fixed array).
MAX_CLIENTS = 4

serial_tcp_ns = cg.esphome_ns.namespace("serial_tcp")
SerialTcpServer = serial_tcp_ns.class_(
    "SerialTcpServer", cg.Component, uart.UARTDevice
)


def _power_of_two(value):
    """The buffer is indexed with a mask: its size must be a power of two."""
    value = cv.int_range(min=64, max=16384)(value)
    if value & (value - 1):
        raise cv.Invalid(f"buffer_size must be a power of two (64..16384), not {value}")
    return value


def _consume_sockets(config):
    """Tell ESPHome how many lwIP sockets this port needs, so it sizes the table."""
    socket.consume_sockets(config[CONF_MAX_CLIENTS], "serial_tcp")(config)
    socket.consume_sockets(1, "serial_tcp", socket.SocketType.TCP_LISTEN)(config)
    return config


CONFIG_SCHEMA = cv.All(
    cv.Schema(
        {
            cv.GenerateID(): cv.declare_id(SerialTcpServer),
            cv.Required(CONF_PORT): cv.port,
            cv.Optional(CONF_BUFFER_SIZE, default=1024): _power_of_two,
            cv.Optional(CONF_MAX_CLIENTS, default=1): cv.int_range(
                min=1, max=MAX_CLIENTS
            ),
        }
    )
    .extend(cv.COMPONENT_SCHEMA)
    .extend(uart.UART_DEVICE_SCHEMA),
    _consume_sockets,
)

def FINAL_VALIDATE_SCHEMA(config):
    """Bytes go both ways (reports from the radar, commands to it): the UART
    needs both pins. On the host platform (a Linux build, which the tests run)
    a UART is a device path with no pins, so there is nothing to check."""
    if CORE.is_host:
        return config
    return uart.final_validate_device_schema(
        "serial_tcp", require_tx=True, require_rx=True
    )(config)


async def to_code(config):
    var = cg.new_Pvariable(config[CONF_ID])
    cg.add(var.set_port(config[CONF_PORT]))
    cg.add(var.set_buffer_size(config[CONF_BUFFER_SIZE]))
    cg.add(var.set_max_clients(config[CONF_MAX_CLIENTS]))
    await cg.register_component(var, config)
    await uart.register_uart_device(var, config)
