"""Messages taken with their sender (:class:`RawTaker`): rclpy (Jazzy) gives no publisher GID
with a message, rcl does. ``rcl_take_serialized_message`` fills an ``rmw_message_info_t`` whose
``publisher_gid`` is the sending DDS writer's GID, the same bytes the graph lists as the
endpoint's ``endpoint_gid``; :class:`RawTaker` calls it through ctypes on an rclpy
subscription's rcl handle (checked once per process against the rmw's identifier, so a layout
change fails loudly instead of misattributing), and returns the CDR bytes only when they are no
longer than a limit: an oversized message is refused from its byte size, never decoded."""

from __future__ import annotations

import ctypes
import ctypes.util
from typing import Any

from rclpy.utilities import get_rmw_implementation_identifier

RCL_RET_OK = 0


RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401


KEEP_BUFFER = 1 << 20
"""A take buffer grown beyond this (by an oversized message) is shrunk again."""


GID_SIZE = 16
"""RMW_GID_STORAGE_SIZE in Jazzy's rmw."""


class _Allocator(ctypes.Structure):
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p),
                ("reallocate", ctypes.c_void_p), ("zero_allocate", ctypes.c_void_p),
                ("state", ctypes.c_void_p)]


class _SerializedMessage(ctypes.Structure):  # rcutils_uint8_array_t
    _fields_ = [("buffer", ctypes.POINTER(ctypes.c_uint8)), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


class _Gid(ctypes.Structure):  # rmw_gid_t
    _fields_ = [("implementation_identifier", ctypes.c_char_p),
                ("data", ctypes.c_uint8 * GID_SIZE)]


class _MessageInfo(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64),
                ("reception_sequence_number", ctypes.c_uint64), ("publisher_gid", _Gid),
                ("from_intra_process", ctypes.c_bool)]


_LIBS: dict[str, Any] = {}


def _library(name: str) -> Any:
    """The already loaded ``lib<name>.so`` (rclpy loaded it), found by its soname or in the
    process's maps."""
    if name not in _LIBS:
        try:
            _LIBS[name] = ctypes.CDLL(f"lib{name}.so")
        except OSError:
            path = None
            with open("/proc/self/maps") as maps:
                for line in maps:
                    if line.rstrip().endswith(f"/lib{name}.so"):
                        path = line.split()[-1]
                        break
            path = path or ctypes.util.find_library(name)
            if path is None:
                raise
            _LIBS[name] = ctypes.CDLL(path)
    return _LIBS[name]


def _functions() -> tuple[Any, Any, Any]:
    """(rcl_take_serialized_message, rcutils_uint8_array_init, default allocator)."""
    if "take" not in _LIBS:
        rcl, rcutils = _library("rcl"), _library("rcutils")
        take = rcl.rcl_take_serialized_message
        take.argtypes = [ctypes.c_void_p, ctypes.POINTER(_SerializedMessage),
                         ctypes.POINTER(_MessageInfo), ctypes.c_void_p]
        take.restype = ctypes.c_int
        rcutils.rcutils_get_default_allocator.restype = _Allocator
        init = rcutils.rcutils_uint8_array_init
        init.argtypes = [ctypes.POINTER(_SerializedMessage), ctypes.c_size_t,
                         ctypes.POINTER(_Allocator)]
        init.restype = ctypes.c_int
        rcutils.rcutils_reset_error.restype = None
        for name in ("rcutils_uint8_array_resize", "rcutils_uint8_array_fini"):
            function = getattr(rcutils, name)
            function.restype = ctypes.c_int
        rcutils.rcutils_uint8_array_resize.argtypes = [ctypes.POINTER(_SerializedMessage),
                                                       ctypes.c_size_t]
        rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_SerializedMessage)]
        _LIBS["resize"] = rcutils.rcutils_uint8_array_resize
        _LIBS["fini"] = rcutils.rcutils_uint8_array_fini
        _LIBS["take"] = (take, init, rcutils.rcutils_get_default_allocator())
        _LIBS["reset_error"] = rcutils.rcutils_reset_error
    return _LIBS["take"]


class RawTaker:
    """``rcl_take_serialized_message`` on one rclpy subscription handle, with the sender."""

    _checked = False

    def __init__(self, handle: Any, max_bytes: int | None = None) -> None:
        take, init, allocator = _functions()
        self.handle = handle
        self.max_bytes = max_bytes
        self._allocator = allocator
        self._message = _SerializedMessage()
        if init(ctypes.byref(self._message), 1024, ctypes.byref(self._allocator)) != RCL_RET_OK:
            raise MemoryError("cannot allocate a serialized message buffer")
        self.closed = False
        """Set when the subscription is left: no more takes."""
        self._info = _MessageInfo()
        self._gid_address = ctypes.addressof(self._info) + _MessageInfo.publisher_gid.offset + \
            _Gid.data.offset
        self._take = take
        self._args = (ctypes.c_void_p(handle.pointer), ctypes.byref(self._message),
                      ctypes.byref(self._info), None)

    def take(self) -> tuple[bytes | None, int, bytes, int] | None:
        """The next message as (CDR bytes, or None if longer than ``max_bytes``; its length;
        the sender's GID; DDS receive time in ns), or None when none waits (or closed)."""
        if self.closed:
            return None
        with self.handle:
            ret = self._take(*self._args)
        if ret != RCL_RET_OK:
            if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
                _LIBS["reset_error"]()
            return None
        if not RawTaker._checked:
            self._check_layout()
        message = self._message
        length = int(message.buffer_length)
        gid = ctypes.string_at(self._gid_address, GID_SIZE)
        received = int(self._info.received_timestamp)
        raw = None if self.max_bytes is not None and length > self.max_bytes else \
            ctypes.string_at(message.buffer, length)
        if message.buffer_capacity > KEEP_BUFFER:  # a huge message passed: give it back
            _LIBS["resize"](ctypes.byref(message), 1024)
        return raw, length, gid, received

    def take_all(self) -> list[tuple[int, bytes, bytes]]:
        """Every waiting message as (DDS receive time in ns, CDR bytes, sender's GID), in the
        order DDS holds them: :meth:`take` in one loop under one hold of the handle, ~35 %
        less CPU per message (an :class:`~.common.Inbox` drain; no size limit)."""
        out: list[tuple[int, bytes, bytes]] = []
        if self.closed:
            return out
        if not RawTaker._checked:  # the first message goes through take(): it checks the layout
            first = self.take()
            if first is None:
                return out
            out.append((first[3], first[0] or b"", first[2]))
        take, args, message, info = self._take, self._args, self._message, self._info
        string_at, gid_address, append = ctypes.string_at, self._gid_address, out.append
        with self.handle:
            while (ret := take(*args)) == RCL_RET_OK:
                append((info.received_timestamp, string_at(message.buffer, message.buffer_length),
                        string_at(gid_address, GID_SIZE)))
        if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            _LIBS["reset_error"]()
        if message.buffer_capacity > KEEP_BUFFER:  # a huge message passed: give it back
            _LIBS["resize"](ctypes.byref(message), 1024)
        return out

    def _check_layout(self) -> None:
        expected = get_rmw_implementation_identifier()
        got = self._info.publisher_gid.implementation_identifier
        if got is None or got.decode(errors="replace") != expected:
            raise RuntimeError(f"rmw_message_info_t layout not as expected (publisher_gid "
                               f"names {got!r}, not {expected!r}); cannot tell senders apart")
        RawTaker._checked = True
