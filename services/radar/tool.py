"""`buddybot radar ...`: configure an LD2410 on a port (any pyserial URL).

    buddybot radar info --port /dev/ttyUSB0
    buddybot radar engineering on --port socket://esp32.local:8881
    buddybot radar set-gates --moving 6 --still 6 --duration 10 --port URL
    buddybot radar set-sensitivity --gate all --moving 40 --still 30 --port URL
    buddybot radar set-resolution 0.2 --port URL
    buddybot radar restart --port URL      (or factory-reset)

Every verb runs inside enable configuration ... end configuration. The
port must not be read by a running radar bridge at the same time. Exit
status: 0 done, 1 the sensor did not answer or refused, 2 bad usage.
"""

from __future__ import annotations

import argparse
import json
import sys

import serial

from buddybot.core.service import ServiceContext
from buddybot.radar.client import LD2410Client, RadarError
from buddybot.radar.ld2410 import Parameters, ProtocolError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.description = __doc__
    # The action comes first (`buddybot radar info --port URL`): the CLI hands
    # a tool everything after its verb, and options go to every action.
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--port", metavar="URL",
                        help="pyserial URL of the sensor (default: first [radar_bridge] sensor)")
    common.add_argument("--baudrate", type=int, help="serial speed (default 256000)")
    common.add_argument("--timeout", type=float, default=1.0,
                        help="seconds to wait for each ACK (default 1.0)")
    common.add_argument("--json", action="store_true", help="print results as JSON")
    common.add_argument("--config", metavar="FILE", default=argparse.SUPPRESS,
                        help="TOML config file (default: $BUDDYBOT_CONFIG)")
    verbs = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    def action(name: str, help_text: str) -> argparse.ArgumentParser:
        return verbs.add_parser(name, help=help_text, description=help_text, parents=[common])

    action("info", "firmware version, parameters, distance resolution")
    p = action("engineering", "engineering mode (per-gate energies) on or off")
    p.add_argument("state", choices=["on", "off"])
    p = action("set-gates", "farthest moving/still gate and no-one duration")
    p.add_argument("--moving", type=int, help="max moving gate 2..8 (default: keep)")
    p.add_argument("--still", type=int, help="max still gate 2..8 (default: keep)")
    p.add_argument("--duration", type=int, help="no-one duration, s (default: keep)")
    p = action("set-sensitivity", "moving/still sensitivity of a gate or all")
    p.add_argument("--gate", required=True, help="gate 0..8 or 'all'")
    p.add_argument("--moving", type=int, required=True, help="0..100")
    p.add_argument("--still", type=int, required=True, help="0..100")
    p = action("set-resolution", "metres per gate: 0.75 (default) or 0.2")
    p.add_argument("metres", type=float, choices=[0.75, 0.2])
    action("restart", "restart the module")
    action("factory-reset", "restore factory settings (effective after restart)")


def _params_dict(params: Parameters) -> dict[str, object]:
    return {
        "max_gate": params.max_gate,
        "max_moving_gate": params.max_moving_gate,
        "max_still_gate": params.max_still_gate,
        "moving_sensitivity": list(params.moving_sensitivity),
        "still_sensitivity": list(params.still_sensitivity),
        "no_one_duration_s": params.no_one_duration_s,
    }


def execute(client: LD2410Client, args: argparse.Namespace) -> dict[str, object]:
    """Run one action (inside enable/end configuration); returns what to print."""
    with client.configuring() as enable:
        result: dict[str, object] = {}
        action = args.action
        if action == "info":
            result["firmware"] = client.read_firmware()
            result["protocol_version"] = enable.protocol_version
            result["parameters"] = _params_dict(client.read_parameters())
            result["resolution_m"] = client.read_resolution()
        elif action == "engineering":
            client.set_engineering(args.state == "on")
            result["engineering"] = args.state
        elif action == "set-gates":
            current = client.read_parameters()
            moving = current.max_moving_gate if args.moving is None else args.moving
            still = current.max_still_gate if args.still is None else args.still
            duration = current.no_one_duration_s if args.duration is None else args.duration
            client.set_max_gates(moving, still, duration)
            result["parameters"] = _params_dict(client.read_parameters())
        elif action == "set-sensitivity":
            gate = None if args.gate == "all" else int(args.gate)
            client.set_sensitivity(gate, args.moving, args.still)
            result["parameters"] = _params_dict(client.read_parameters())
        elif action == "set-resolution":
            client.set_resolution(args.metres)
            result["resolution_m"] = client.read_resolution()
            result["note"] = "takes effect after a restart"
        elif action == "restart":
            client.restart()
            result["restarted"] = True
        elif action == "factory-reset":
            client.factory_reset()
            result["factory_reset"] = True
            result["note"] = "takes effect after a restart"
    return result


def _print(result: dict[str, object], as_json: bool) -> None:
    if as_json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        if isinstance(value, dict):
            print(f"{key}:")
            for k, v in value.items():
                print(f"  {k}: {v}")
        else:
            print(f"{key}: {value}")


def run(ctx: ServiceContext) -> int:
    args = ctx.args
    cfg = ctx.config.radar_bridge
    url = args.port or (cfg.sensors[0] if cfg.sensors else None)
    if not url:
        print("buddybot radar: no port: give --port URL", file=sys.stderr)
        return 2
    if args.action == "set-sensitivity" and args.gate != "all" and not args.gate.isdigit():
        print("buddybot radar: --gate must be 0..8 or 'all'", file=sys.stderr)
        return 2
    try:
        port = serial.serial_for_url(url, baudrate=args.baudrate or cfg.baudrate, timeout=0.05)
    except (serial.SerialException, OSError, ValueError) as exc:
        print(f"buddybot radar: cannot open {url}: {exc}", file=sys.stderr)
        return 1
    try:
        result = execute(LD2410Client(port, timeout_s=args.timeout), args)
    except ProtocolError as exc:
        print(f"buddybot radar: {exc}", file=sys.stderr)
        return 2 if args.action.startswith("set-") else 1
    except (RadarError, serial.SerialException, OSError) as exc:
        print(f"buddybot radar: {url}: {exc}", file=sys.stderr)
        return 1
    finally:
        port.close()
    _print(result, args.json)
    return 0
