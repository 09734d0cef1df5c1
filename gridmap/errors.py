"""The project's one root exception. Every package's own error class derives from it, so a
front end (the command line, the ROS node) catches one type and prints one line."""


class MapUpdatingError(Exception):
    """Bad input or a failed operation a user can act on; the message names the file, key or
    value at fault."""
