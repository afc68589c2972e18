"""The project's exception root: every error a user can cause derives from SonarSlamError."""


class SonarSlamError(Exception):
    """Base class for errors reported to the user as one line, never a traceback."""


class WorldError(SonarSlamError, ValueError):
    """A world file is missing, malformed or geometrically invalid."""


class ConfigError(SonarSlamError, ValueError):
    """A configuration file or value is invalid."""


class MapFormatError(SonarSlamError, ValueError):
    """A map file cannot be read or does not fit the expected grid."""


class LogFormatError(SonarSlamError, ValueError):
    """A recorded sensor log cannot be read."""


class HardwareError(SonarSlamError, RuntimeError):
    """A hardware device is missing, misconfigured or misbehaving."""
