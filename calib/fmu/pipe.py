"""The pipe protocol between a worker process and its supervisor: length-prefixed pickles.

A message is any picklable object, written as its pickle's length (8 bytes, little-endian
unsigned) followed by the pickle. :func:`write_message` writes one to a file descriptor,
:func:`read_message` reads the next one (None when the other end has closed the pipe). Both
the child (:mod:`calib.fmu.child`) and the supervisor (:class:`calib.fmu.worker.WorkerProcess`)
speak it.
"""

from __future__ import annotations

import os
import pickle
import struct


def write_message(fd: int, obj) -> None:
    """Write ``obj`` as one message to the file descriptor ``fd`` (all of it, however many writes).

    Parameters
    ----------
    fd : int
        A file descriptor open for writing (a pipe).
    obj : object
        Any picklable object.
    """
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    payload = struct.pack("<Q", len(data)) + data
    view = memoryview(payload)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exact(fd: int, n: int) -> bytes | None:
    chunks, got = [], 0
    while got < n:
        b = os.read(fd, n - got)
        if not b:
            return None
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def read_message(fd: int):
    """The next message on the file descriptor ``fd``.

    Parameters
    ----------
    fd : int
        A file descriptor open for reading (a pipe).

    Returns
    -------
    object or None
        The object written by :func:`write_message`; None when the pipe closed before a whole
        message arrived (the writer ended).
    """
    head = _read_exact(fd, 8)
    if head is None:
        return None
    body = _read_exact(fd, struct.unpack("<Q", head)[0])
    return None if body is None else pickle.loads(body)
