"""robot.nxt: the LEGO Mindstorms NXT as a `Robot`: its direct-command protocol over a serial
port (`protocol`), the driver (`driver.NXTRobot`) and an emulated brick on a pseudo-terminal
(`emulator.NXTEmulator`) for tests and `nxt:emulator`."""

from robot.nxt.driver import LinkConfig, NXTRobot, NXTRobotConfig, RobotConnectionError
from robot.nxt.emulator import EmulatorConfig, NXTEmulator

__all__ = ["EmulatorConfig", "LinkConfig", "NXTEmulator", "NXTRobot", "NXTRobotConfig", "RobotConnectionError"]
