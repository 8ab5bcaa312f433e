"""The one error class for bad input. Every command ends on such an error with one line on stderr, exit 2."""


class InputError(ValueError):
    """Bad input from the user: a config value, a file, an argument, an annotation.

    Subclasses say where it came from (ConfigError, RobotSpecError, PolicyFileError, AnnotationError,
    CheckpointError, CalibrationError); the message names what is wrong and where.
    """
