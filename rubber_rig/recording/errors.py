"""Errors of the recording package: one clear message naming the file and the problem."""


class RecordingError(ValueError):
    """A recording cannot be read or written (malformed, truncated, unwritable, ...)."""


class RecordingWriteError(RecordingError):
    """Writing failed (disk full, file too large, path not writable); what was flushed stays readable."""

    def __init__(self, message: str, errno: int = 0):
        super().__init__(message)
        self.errno = errno
