"""User-facing errors: each message is one line naming the file or value at fault."""


class ConfigError(ValueError):
  """A bad configuration value, binding or config file."""


class DataError(ValueError):
  """Missing, malformed or inconsistent input data."""


class RunDirError(RuntimeError):
  """A run directory that cannot be used without losing earlier results."""


class DistributedError(RuntimeError):
  """A multi-process run that cannot start: bad process flags, a coordinator not
  reached."""


USER_ERRORS = (ConfigError, DataError, RunDirError, DistributedError)
