"""`buddybot run eyes`: the eyes driver service.

The arbiter (`arbiter.py`) decides what the eyes show, the built-in
behaviour's wish or a lease holder's command, and puts it on
`eyes/expression` / `eyes/control`; this adapter turns the winner into
`eyes/direction` + `eyes/pupil` and `eyes/lids` (latched, so a renderer
that starts later gets the current lids) through `buddybot.eyes.driver`.
The mapping is microseconds of arithmetic, so it runs inline in Zenoh's
callback thread; malformed samples are dropped and counted by the node
runtime, never fatal.
"""

from __future__ import annotations

import argparse

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes import driver
from buddybot.eyes.arbiter import Arbiter
from buddybot.eyes.settings import EyesSettings
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The option overrides its `[eyes]` key (default and range: settings.py)."""
    settings_option(parser, "--unknown-distance-percent", struct=EyesSettings,
                    field="unknown_distance_percent", metavar="PCT")


def settings_from(ctx: ServiceContext) -> EyesSettings:
    """`[eyes]` with the command line on top (range checked by `merge`)."""
    return merge(ctx.config.section(EyesSettings), ctx.args)


def build(ctx: ServiceContext) -> tuple[driver.PupilCurve, float, dict]:
    """Validate the merged `[eyes]` into the driver's pure objects (ConfigError naming
    the key)."""
    return build_from(settings_from(ctx))


def build_from(settings: EyesSettings) -> tuple[driver.PupilCurve, float, dict]:
    """`build` for a given struct: at start and for each live parameter change."""
    try:
        curve = driver.PupilCurve.from_points(settings.pupil_curve)
    except ValueError as exc:
        raise ConfigError(f"key 'eyes.pupil_curve': {exc}") from None
    try:
        table = driver.lid_table(settings.lids)
    except ValueError as exc:
        raise ConfigError(f"key 'eyes.lids': {exc}") from None
    return curve, settings.unknown_distance_percent, table


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    # One tuple, replaced whole by a live change: a handler reads a consistent set.
    built = [build_from(settings)]
    last: list[m.ScreenExpression] = []
    node = ctx.node()
    try:
        direction_pub = node.publisher(keys.EYES_DIRECTION)
        pupil_pub = node.publisher(keys.PUPIL)
        lids_pub = node.publisher(keys.LIDS)
        diag = node.diagnostics

        def on_control(control: m.EyeControl | None, pupil: m.PupilControl | None) -> None:
            curve, unknown, _table = built[0]
            if control is not None:
                direction_pub.put(driver.direction_from_control(control))
                diag.increment("controls")
            if pupil is None and control is not None:
                pupil = driver.pupil_from_control(control, curve, unknown)
            if pupil is not None:
                pupil_pub.put(pupil)

        def on_expression(expression: m.ScreenExpression) -> None:
            last[:] = [expression]
            for lids in driver.lids_for_expression(expression, built[0][2]):
                lids_pub.put(lids)
            diag.increment("expressions")
            diag.values["expression"] = expression.action.name

        def show(expression: m.ScreenExpression | None, control: m.EyeControl | None,
                 pupil: m.PupilControl | None) -> None:
            if expression is not None:
                on_expression(expression)
            on_control(control, pupil)

        arbiter = Arbiter(node, show, settings.lease_actions_per_s,
                          settings.lease_actions_burst)

        def apply(new: EyesSettings) -> None:
            """A live change (`buddybot param set eyes ...`): a curve or lid table the
            driver cannot use is refused (ValueError); new lids are shown at once."""
            built[0] = build_from(new)
            arbiter.set_rates(new.lease_actions_per_s, new.lease_actions_burst)
            for expression in last[-1:]:
                for lids in driver.lids_for_expression(expression, built[0][2]):
                    lids_pub.put(lids)

        LiveSettings(settings, apply).serve(node)
        arbiter.start()
        node.every(1.0, lambda: diag.values.update(arbiter.counters), "diagnostics")
        node.log.info("eyes driver ready")
        node.spin()
    finally:
        node.close()
    return 0
