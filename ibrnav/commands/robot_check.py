"""`ibrnav robot check --port /dev/rfcomm0`: is the NXT there and working? Reports the
battery, every sensor, and turns each wheel a little (a short motor pulse)."""

from __future__ import annotations

import argparse
import time

import numpy as np


def run(args: argparse.Namespace) -> int:
    from robot.nxt.driver import LinkConfig, NXTRobot, NXTRobotConfig

    emulator = None
    port = args.port
    if args.emulator:
        from robot.nxt.emulator import EmulatorConfig, NXTEmulator

        emulator = NXTEmulator(EmulatorConfig(time_scale=4.0))
        port = emulator.port
    try:
        with NXTRobot(port, NXTRobotConfig(), link_config=LinkConfig(timeout_s=args.timeout)) as robot:
            print(f"NXT on {port}")
            print(f"  battery        {robot.battery_mv() / 1000:.2f} V")
            print(f"  sleep timeout  {robot.brick.keep_alive() / 60000:.0f} min")
            front, rear = robot.bumpers()
            print(f"  bumpers        front {'pressed' if front else 'free'}, rear {'pressed' if rear else 'free'}")
            print(f"  ultrasonic     {robot.ultrasonic():.2f} m")
            print(f"  compass        {np.degrees(robot.compass()):.0f} deg (world frame)")
            for name, port_ in (("left wheel", robot.config.left_motor), ("right wheel", robot.config.right_motor)):
                print(f"  {name:<14} turned {pulse(robot, port_, args.pulse_deg):+.0f} deg "
                      f"of {args.pulse_deg:.0f} commanded")
    finally:
        if emulator is not None:
            emulator.close()
    return 0


def pulse(robot, port: int, degrees: float, power: int = 30, timeout_s: float = 3.0) -> float:
    """Run one motor of an `NXTRobot` `degrees` forward at low power, brake; the degrees it turned."""
    from robot.nxt import protocol as P

    b = robot.brick
    start = b.get_output_state(port).rotation_count
    b.set_output_state(port, power, P.MODE_ON | P.MODE_BRAKE | P.MODE_REGULATED, P.REGULATION_SPEED, 0,
                       P.RUN_RUNNING, int(degrees))
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            time.sleep(0.05)
            state = b.get_output_state(port)
            if state.run_state == P.RUN_IDLE or abs(state.rotation_count - start) >= degrees - 1:
                break
    finally:
        b.brake(port)
    return float(b.get_output_state(port).rotation_count - start)


def register(subparsers) -> None:
    p = subparsers.add_parser("robot", help="the real robot (LEGO NXT over Bluetooth serial)")
    sub = p.add_subparsers(dest="robot_command", required=True, metavar="ROBOT_COMMAND")
    c = sub.add_parser("check", help="battery, sensors and a short motor pulse of the NXT on a serial port")
    c.add_argument("--port", default="/dev/rfcomm0", help="the NXT's serial port (or a pyserial URL)")
    c.add_argument("--emulator", action="store_true", help="check against the built-in NXT emulator instead")
    c.add_argument("--pulse-deg", type=float, default=90.0, help="how far to turn each wheel (degrees)")
    c.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for each reply")
    c.set_defaults(func=run)
