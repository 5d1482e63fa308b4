"""`hapticop lidar ...`, `hapticop falcon ...` and `hapticop devices`: looking at captures and devices by hand."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import typer

lidar = typer.Typer(help="SICK TiM5xx telegrams.", no_args_is_help=True, add_completion=False)
falcon = typer.Typer(help="Novint Falcon kinematics (libnifalcon geometry).", no_args_is_help=True,
                     add_completion=False)


def _plain(value):
    if isinstance(value, bytes):
        return value.decode("latin-1")
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.generic):
        return value.item()
    return value


@lidar.command("decode")
def lidar_decode(
    file: Path = typer.Argument(..., help="one LMDscandata telegram (sRA or sSN, with or without STX/ETX)"),
    json_output: bool = typer.Option(False, "--json", help="every field and every range as JSON"),
) -> None:
    """Print a telegram's header fields and its ranges in metres (NaN: no valid echo)."""
    from hapticop.devices.sick.cola import ColaError
    from hapticop.devices.sick.scan import parse_scan

    try:
        body = file.read_bytes()
        header = parse_scan(body, None)
        points = header.dist.count if hasattr(header.dist, "count") else None
        ranges = np.zeros(points or 10_000, dtype=np.float64)
        angles = np.zeros_like(ranges)
        header = parse_scan(body, ranges, angles)
    except OSError as error:
        typer.echo(f"error: cannot read {file}: {error.strerror}", err=True)
        raise typer.Exit(2) from None
    except ColaError as error:
        typer.echo(f"error: {file} is not a scan telegram: {error}", err=True)
        raise typer.Exit(1) from None
    n = points or len(ranges)
    ranges, angles = ranges[:n], angles[:n]
    if json_output:
        typer.echo(json.dumps({"header": _plain(header), "angles_rad": angles.tolist(),
                               "ranges_m": [None if np.isnan(r) else r for r in ranges.tolist()]}, indent=1))
        return
    for field in dataclasses.fields(header):
        value = _plain(getattr(header, field.name))
        if field.name in _RAW_UNITS:
            typer.echo(f"{field.name:24s} {value} {_RAW_UNITS[field.name](value)}")
        elif field.name in ("channels16", "channels8"):
            for channel in value:
                typer.echo(f"{field.name:24s} {_channel_text(channel)}")
        elif field.name != "dist":
            typer.echo(f"{field.name:24s} {value}")
    valid = ~np.isnan(ranges)
    typer.echo(f"{'points':24s} {n} over {np.degrees(angles[-1] - angles[0]):.1f} deg, {int(valid.sum())} valid")
    if valid.any():
        typer.echo(f"{'range min / max':24s} {np.nanmin(ranges):.3f} / {np.nanmax(ranges):.3f} m")
    for i in range(0, n, max(1, n // 9)):
        typer.echo(f"  [{i:4d}] {np.degrees(angles[i]):8.3f} deg  {ranges[i]:.3f} m")


# The telegram's integer fields in the sensor's own units, each with its name and its value in SI
_RAW_UNITS = {
    "scan_frequency": lambda v: f"(1/100 Hz: {v / 100:g} Hz)",
    "measurement_frequency": lambda v: f"(100 Hz: {v * 100 / 1000:g} kHz between neighbouring points)",
}


def _channel_text(channel: dict) -> str:
    """A data channel with its angles in degrees (the telegram has 1/10000 degree) and its scale."""
    return (f"{channel['name']}: {channel['count']} values from {channel['start_angle']} "
            f"(1/10000 deg: {channel['start_angle'] / 10000:g} deg) in steps of {channel['angular_step']} "
            f"(1/10000 deg: {channel['angular_step'] / 10000:g} deg), value x {channel['scale_factor']:g} "
            f"+ {channel['scale_offset']:g}" + (" mm" if channel["name"].startswith("DIST") else ""))


def _kinematics():
    from hapticop.devices.falcon import WORKSPACE_CENTRE_M, FalconKinematics

    return FalconKinematics(), np.asarray(WORKSPACE_CENTRE_M)


@falcon.command("fk", context_settings={"ignore_unknown_options": True})
def falcon_fk(
    e1: int = typer.Argument(..., help="encoder counts of leg 1"),
    e2: int = typer.Argument(..., help="leg 2"),
    e3: int = typer.Argument(..., help="leg 3"),
    json_output: bool = typer.Option(False, "--json"),
) -> None:
    """Handle position (m, device frame) of three encoder counts, solved to 1e-10 m."""
    kinematics, centre = _kinematics()
    position, angles = np.zeros(3), np.zeros(3)
    kinematics.angles_from_counts([e1, e2, e3], angles)
    if not kinematics.forward([e1, e2, e3], position):
        typer.echo(f"error: counts ({e1}, {e2}, {e3}) are outside the Falcon's reachable workspace", err=True)
        raise typer.Exit(1)
    data = {"counts": [e1, e2, e3], "thigh_angles_rad": angles.tolist(), "position_m": position.tolist(),
            "from_workspace_centre_m": (position - centre).tolist(), "iterations": kinematics.iterations}
    if json_output:
        typer.echo(json.dumps(data, indent=1))
        return
    typer.echo(f"position      x {position[0]:+.6f}  y {position[1]:+.6f}  z {position[2]:+.6f} m")
    typer.echo(f"from centre   x {position[0] - centre[0]:+.6f}  y {position[1] - centre[1]:+.6f}  "
               f"z {position[2] - centre[2]:+.6f} m")
    typer.echo(f"thigh angles  {' '.join(f'{a:+.6f}' for a in angles)} rad  ({kinematics.iterations} iterations)")


@falcon.command("ik", context_settings={"ignore_unknown_options": True})
def falcon_ik(
    x: float = typer.Argument(..., help="handle position x, m (device frame)"),
    y: float = typer.Argument(..., help="y, m"),
    z: float = typer.Argument(..., help="z, m (the workspace centre is at z = 0.125)"),
    json_output: bool = typer.Option(False, "--json"),
) -> None:
    """Thigh angles and encoder counts of a handle position."""
    kinematics, _ = _kinematics()
    angles, counts = np.zeros(3), np.zeros(3, dtype=np.int64)
    if not kinematics.inverse([x, y, z], angles):
        from hapticop.devices.falcon import WORKSPACE_BOX_M

        (x0, y0, z0), (x1, y1, z1) = WORKSPACE_BOX_M
        typer.echo(f"error: ({x}, {y}, {z}) m is outside the Falcon's reachable workspace: the handle reaches "
                   f"about x {x0:+.3f} to {x1:+.3f}, y {y0:+.3f} to {y1:+.3f}, z {z0:.3f} to {z1:.3f} m "
                   f"(device frame; not every corner of that box)", err=True)
        raise typer.Exit(1)
    kinematics.counts_from_angles(angles, counts)
    data = {"position_m": [x, y, z], "thigh_angles_rad": angles.tolist(), "counts": counts.tolist()}
    if json_output:
        typer.echo(json.dumps(data, indent=1))
        return
    typer.echo(f"thigh angles  {' '.join(f'{a:+.6f}' for a in angles)} rad")
    typer.echo(f"counts        {' '.join(str(int(c)) for c in counts)}")


def _host_port(text: str, default_port: int) -> tuple[str, int]:
    """HOST, HOST:PORT, [V6]:PORT or a bare IPv6 address."""
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        return host, int(rest[1:]) if rest.startswith(":") else default_port
    if text.count(":") == 1:
        host, port = text.split(":")
        return host, int(port)
    return text, default_port


def devices(
    lidar: list[str] = typer.Option([], "--lidar", metavar="HOST[:PORT]",
                                    help="probe a TiM5xx there over CoLa A (port 2112 by default); repeatable"),
    usb: bool = typer.Option(True, "--usb/--no-usb", help="list the Falcons on USB"),
    timeout: float = typer.Option(2.0, min=0.05, help="seconds to wait for a LIDAR"),
    json_output: bool = typer.Option(False, "--json"),
    usb_backend: str = typer.Option("libusb", hidden=True, help="'virtual': one virtual Falcon (demos, tests)"),
) -> None:
    """List the Falcons on USB and probe LIDAR addresses; exit 1 if something cannot be reached."""
    from hapticop.devices.falcon.usb_driver import describe_falcons, system_backend
    from hapticop.devices.falcon.usb_errors import FalconUsbError
    from hapticop.devices.sick.probe import ProbeError, probe_lidar

    if not usb and not lidar:
        typer.echo("nothing to look for: --no-usb skips the Falcons and no --lidar HOST[:PORT] was given; "
                   "try `hapticop devices` (Falcons on USB) or `hapticop devices --no-usb --lidar 192.168.0.1`",
                   err=True)
        raise typer.Exit(2)
    report: dict = {}
    failed = False
    if usb:
        try:
            if usb_backend == "virtual":
                from hapticop.devices.falcon.virtual_clock import WallClock
                from hapticop.devices.falcon.virtual_falcon import VirtualFalcon
                from hapticop.devices.falcon.virtual_usb import VirtualUsbBackend

                backend = VirtualUsbBackend(VirtualFalcon(WallClock()))
            else:
                backend = system_backend()
            falcons = describe_falcons(backend)
            report["falcons"] = [dataclasses.asdict(f) for f in falcons]
            failed |= any(f.problem for f in falcons)
        except FalconUsbError as error:
            report["falcons"], report["usb_error"] = [], str(error)
            failed = True
    lidars = []
    for address in lidar:
        try:
            host, port = _host_port(address, 2112)
        except ValueError:
            lidars.append({"address": address, "error": f"{address!r} is not HOST or HOST:PORT"})
            failed = True
            continue
        try:
            lidars.append({"address": f"{host}:{port}", **dataclasses.asdict(probe_lidar(host, port, timeout))})
        except ProbeError as error:
            lidars.append({"address": f"{host}:{port}", "error": str(error)})
            failed = True
    if lidar:
        report["lidars"] = lidars
    if json_output:
        typer.echo(json.dumps(report, indent=1))
    else:
        _print_devices(report, usb)
    raise typer.Exit(1 if failed else 0)


def _print_devices(report: dict, usb: bool) -> None:
    if usb:
        typer.echo("Falcons on USB (0403:CB48):")
        if "usb_error" in report:
            typer.echo(f"  error: {report['usb_error']}")
        elif not report["falcons"]:
            typer.echo("  none found: is the Falcon plugged in, and its own power supply connected?")
        for f in report["falcons"]:
            where = f"  [{f['index']}] bus {f['bus']} address {f['address']}"
            if f["problem"]:
                typer.echo(f"{where}: error: {f['problem']}")
                continue
            state = ("firmware running" if f["firmware_running"]
                     else "no firmware loaded (the Falcon block loads it from the image you give)")
            typer.echo(f"{where}, serial {f['serial']}, {f['product']}: {state}")
    for entry in report.get("lidars", []):
        if "error" in entry:
            typer.echo(f"LIDAR {entry['address']}: error: {entry['error']}")
        else:
            state = f", state {entry['state']}" if entry["state"] else ""
            typer.echo(f"LIDAR {entry['address']}: {entry['device_type']}, firmware {entry['firmware']}, "
                       f"serial {entry['serial']}{state}")
