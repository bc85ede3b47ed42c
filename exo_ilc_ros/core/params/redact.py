"""Credentials never leave the process: the password of a URL (``postgresql://user:pass@host``,
a Dask address) as ``***`` in everything printed, logged or recorded (issue 25)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

PASSWORD_IN_URL = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*://[^:/@\s]*:)[^@\s]+(@)")
"""``scheme://user:`` then the password up to the ``@`` of the host."""
USER_PASSWORD_HOST = re.compile(r"(?<![\w/:])([\w.%+-]+:)[^@\s/:'\"]+(@[\w.-]+)")
"""``user:password@host`` without a scheme (a library quoting the address it parsed)."""


def secrets_in(words: Sequence[str]) -> list[str]:
    """The passwords of the URLs among ``words`` (a command line), to redact wherever they
    appear, whatever a library made of the URL."""
    found = []
    for word in words:
        for match in re.finditer(r"[A-Za-z][A-Za-z0-9+.-]*://[^:/@\s]*:([^@\s]+)@", word):
            found.append(match.group(1))
    return found


def redact(text: str, secrets: Sequence[str] = ()) -> str:
    """``text`` with the password of every URL in it as ``***`` (and every one of
    ``secrets``)."""
    for secret in secrets:
        text = text.replace(secret, "***")
    return USER_PASSWORD_HOST.sub(r"\1***\2", PASSWORD_IN_URL.sub(r"\1***\2", text))


def redact_values(value: Any) -> Any:
    """``value`` (a JSON-like tree of dicts, lists and strings) with every string redacted."""
    if isinstance(value, str):
        return redact(value)
    if isinstance(value, dict):
        return {k: redact_values(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [redact_values(v) for v in value]
    return value


def hide_password(url: str) -> str:
    """A database URL as it may be printed: its password as *** (SQLAlchemy's reading of it,
    imported here: only ``tune --storage`` needs it)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        return make_url(url).render_as_string(hide_password=True)
    except (ArgumentError, ValueError):
        return url
