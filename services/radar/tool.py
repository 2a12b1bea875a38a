"""`buddybot radar ...`: configure an LD2410 or LD2450 on a port (any pyserial URL).

    buddybot radar info --port /dev/ttyUSB0
    buddybot radar engineering on --port socket://esp32.local:8881
    buddybot radar set-gates --moving 6 --still 6 --duration 10 --port URL
    buddybot radar set-sensitivity --gate all --moving 40 --still 30 --port URL
    buddybot radar set-resolution 0.2 --port URL
    buddybot radar restart --port URL      (or factory-reset)
    buddybot radar baud-rate 115200 --port URL
    buddybot radar bluetooth off --port URL
    buddybot radar mac --port URL
    buddybot radar auto-thresholds --duration 10 --wait --port URL   (LD2410C)
    buddybot radar noise-status --port URL                           (LD2410C)
    buddybot radar bluetooth-auth --password HiLink --port URL       (LD2410C)
    buddybot radar bluetooth-password NEWPW1 --port URL              (LD2410C)
    buddybot radar firmware --port URL                               (both models)
    buddybot radar tracking-mode multi --port URL                    (LD2450; or single, query)
    buddybot radar zones --port URL                                  (LD2450)
    buddybot radar set-zones --mode ignore-inside --zone=-500,0,500,1500 --port URL  (LD2450)

restart, factory-reset, baud-rate, bluetooth and mac work on both models.

Every verb runs inside enable configuration ... end configuration. The
port must not be read by a running radar bridge at the same time. Exit
status: 0 done, 1 the sensor did not answer or refused, 2 bad usage.
"""

from __future__ import annotations

import argparse
import json
import time

import serial

from buddybot.radar import ld2410, ld2450
from buddybot.radar.client import LD2410Client, RadarError
from buddybot.radar.ld2410 import Parameters, ProtocolError
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.runtime import options
from buddybot.runtime.errors import DeviceError, UsageError
from buddybot.runtime.limits import clip
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.service import ServiceContext

NOISE_POLL_S = 0.5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.description = __doc__
    # The action comes first (`buddybot radar info --port URL`): the CLI hands
    # a tool everything after its verb, and options go to every action.
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--port", metavar="URL",
                        help="pyserial URL of the sensor (default: first [radar_bridge] sensor)")
    settings_option(common, "--baudrate", struct=RadarBridgeSettings, field="baudrate")
    options.add_timeout_argument(common, 1.0, "seconds to wait for each ACK", connecting=False,
                                 metavar=None, shown="default 1.0")
    options.add_json_argument(common, "print results as JSON")
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
    p = action("baud-rate", "serial speed of the module (effective after restart)")
    p.add_argument("rate", type=int, choices=sorted(ld2410.BAUD_RATES))
    p = action("bluetooth", "the module's Bluetooth on or off (effective after restart)")
    p.add_argument("state", choices=["on", "off"])
    action("mac", "the module's Bluetooth MAC address")
    p = action("auto-thresholds",
               "LD2410C: measure the empty room's background noise and set every "
               "gate's threshold from it (leave the room first)")
    p.add_argument("--duration", type=int, default=10, help="seconds to measure (default 10)")
    p.add_argument("--wait", action="store_true", help="wait until the detection completed")
    action("noise-status", "LD2410C: state of the background noise detection")
    p = action("bluetooth-auth", "LD2410C: obtain Bluetooth permissions with the password")
    p.add_argument("--password", required=True, help="6 ASCII characters (factory: HiLink)")
    p = action("bluetooth-password", "LD2410C: set the Bluetooth password (after restart)")
    p.add_argument("password", help="the new password: 6 printable ASCII characters")
    action("firmware", "the firmware version (LD2410 and LD2450)")
    p = action("tracking-mode", "LD2450: track one target or up to three, or ask which")
    p.add_argument("mode", choices=["single", "multi", "query"])
    action("zones", "LD2450: the zone filter (mode and three rectangles, mm)")
    p = action("set-zones", "LD2450: set the zone filter")
    p.add_argument("--mode", required=True, choices=list(ld2450.ZONE_MODES.values()),
                   help="off; detect-only-inside: only targets inside a zone count; "
                        "ignore-inside: targets inside a zone are dropped")
    p.add_argument("--zone", action="append", default=[], metavar="X1,Y1,X2,Y2",
                   help="a rectangle by two corners in the sensor's x/y, mm (up to 3, "
                        "repeatable; the others are cleared; write --zone=-500,0,500,1500 when "
                        "X1 is negative)")


def _params_dict(params: Parameters) -> dict[str, object]:
    return {
        "max_gate": params.max_gate,
        "max_moving_gate": params.max_moving_gate,
        "max_still_gate": params.max_still_gate,
        "moving_sensitivity": list(params.moving_sensitivity),
        "still_sensitivity": list(params.still_sensitivity),
        "no_one_duration_s": params.no_one_duration_s,
    }


def _zones_dict(zf: ld2450.ZoneFilter) -> dict[str, object]:
    return {"mode": zf.mode_name,
            "zones": [[z.x1, z.y1, z.x2, z.y2] for z in zf.zones if z != ld2450.EMPTY_ZONE]}


def zone_filter(mode: str, zones: list[str]) -> ld2450.ZoneFilter:
    """`--mode`/`--zone` -> the filter; ProtocolError for what the sensor cannot take."""
    numbers = {name: n for n, name in ld2450.ZONE_MODES.items()}
    if len(zones) > ld2450.ZONES:
        raise ProtocolError(f"at most {ld2450.ZONES} zones, got {len(zones)}")
    rects = []
    for text in zones:
        parts = text.split(",")
        if len(parts) != 4 or not all(p.strip().lstrip("-").isdigit() for p in parts):
            raise ProtocolError(f"--zone {text!r}: want X1,Y1,X2,Y2 in mm (integers)")
        rects.append(ld2450.Zone(*(int(p) for p in parts)))
    rects += [ld2450.EMPTY_ZONE] * (ld2450.ZONES - len(rects))
    zf = ld2450.ZoneFilter(numbers[mode], tuple(rects))
    ld2450.encode_zone_filter(zf)  # the range checks
    return zf


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
        elif action == "baud-rate":
            client.set_baud_rate(args.rate)
            result["baud_rate"] = args.rate
            result["note"] = ("takes effect after a restart; then read the sensor with "
                              f"--baudrate {args.rate} ([radar_bridge] baudrate)")
        elif action == "bluetooth":
            client.set_bluetooth(args.state == "on")
            result["bluetooth"] = args.state
            result["note"] = "takes effect after a restart"
        elif action == "mac":
            result["mac"] = client.read_mac()
        elif action == "auto-thresholds":
            client.start_auto_thresholds(args.duration)
            result["noise_detection"] = "started"
            if args.wait:
                result["noise_detection"] = _wait_noise_detection(client, args.duration)
        elif action == "noise-status":
            result["noise_detection"] = client.auto_thresholds_status()
        elif action == "bluetooth-auth":
            client.bluetooth_auth(args.password)
            result["bluetooth_auth"] = "granted"
        elif action == "bluetooth-password":
            client.set_bluetooth_password(args.password)
            result["bluetooth_password"] = "set"
            result["note"] = "takes effect after a restart"
        elif action == "firmware":
            result["firmware"] = client.read_firmware()
            result["protocol_version"] = enable.protocol_version
        elif action == "tracking-mode":
            if args.mode != "query":
                client.set_tracking_mode(args.mode == "multi")
            result["tracking_mode"] = client.read_tracking_mode()
        elif action == "zones":
            result.update(_zones_dict(client.read_zone_filter()))
        elif action == "set-zones":
            client.set_zone_filter(zone_filter(args.mode, args.zone))
            result.update(_zones_dict(client.read_zone_filter()))
    return result


def _wait_noise_detection(client: LD2410Client, duration_s: int) -> str:
    """Poll 0x001B until the detection completed (or clearly never will)."""
    deadline = time.monotonic() + duration_s + 10.0
    status = client.auto_thresholds_status()
    while status != "completed":
        if time.monotonic() > deadline:
            raise RadarError(f"background noise detection not completed after {duration_s} s "
                             f"+ 10 s (status: {status})")
        time.sleep(NOISE_POLL_S)  # the sensor's own pace: nothing to wait on but its answer
        status = client.auto_thresholds_status()
    return status


def _check_values(args: argparse.Namespace) -> None:
    """Refuse bad values before the port is opened (ProtocolError -> exit status 2)."""
    if args.action == "auto-thresholds":
        ld2410.start_auto_thresholds(args.duration)
    elif args.action == "bluetooth-auth":
        ld2410.bluetooth_auth(args.password)
    elif args.action == "bluetooth-password":
        ld2410.set_bluetooth_password(args.password)
    elif args.action == "set-zones":
        zone_filter(args.mode, args.zone)


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
    # The sensor's speed is the bridge's setting: one merge, one range check.
    cfg = merge(ctx.config.section(RadarBridgeSettings), args)
    url = args.port if args.port is not None else (cfg.sensors[0] if cfg.sensors else None)
    if not url:
        raise UsageError("no port: give --port URL")
    if args.action == "set-sensitivity" and args.gate != "all" and not args.gate.isdigit():
        raise UsageError("--gate must be 0..8 or 'all'")
    try:
        _check_values(args)
    except ProtocolError as exc:
        raise UsageError(str(exc)) from None
    try:
        port = serial.serial_for_url(url, baudrate=cfg.baudrate, timeout=0.05)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise DeviceError(f"cannot open {clip(url)}: {clip(str(exc))}") from None
    try:
        result = execute(LD2410Client(port, timeout_s=args.timeout), args)
    except ProtocolError as exc:  # a value the sensor refuses is a usage error
        raise (UsageError if args.action.startswith("set-") else DeviceError)(str(exc)) from None
    except (RadarError, serial.SerialException, OSError) as exc:
        raise DeviceError(f"{clip(url)}: {clip(str(exc))}") from None
    finally:
        port.close()
    _print(result, args.json)
    return 0
