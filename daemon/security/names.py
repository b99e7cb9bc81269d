"""The rules for names that become part of a file name or a bus key, in one place.

* **Identifiers** (camera and sensor ids, the rig name, run names, sweep point ids): a letter or
  digit, then letters, digits, ``.``, ``_`` or ``-``, at most 64 characters (point ids look like
  ``007-up-5.50``). Such a name holds no ``/``, is never ``.`` or ``..``, starts with no ``~``, and
  has no space, control character or key-expression wildcard (``*``, ``$``, ``?``, ``#``), so as a
  file name it stays in its folder and as part of a key it names one key.
* **Identities** (a certificate's common name, the name of its files ``<identity>.pem`` and
  ``<identity>.key``, an access-control subject): stricter, a lowercase letter then lowercase
  letters, digits, ``_`` or ``-``, at most 32 characters.
"""

from __future__ import annotations

import re

IDENTIFIER_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
IDENTITY_RE = re.compile(r"[a-z][a-z0-9_-]{0,31}")


def identifier_problem(value: object, what: str = "name") -> str | None:
    """Why ``value`` cannot be an identifier (text for an error message), or None. O(len)."""
    if not isinstance(value, str):
        return f"{what} must be text, got {type(value).__name__}"
    if IDENTIFIER_RE.fullmatch(value) is None:
        return (
            f"{what} {value[:80]!r} must be 1-64 letters, digits, '.', '_' or '-', starting with a letter "
            "or a digit (it becomes part of file names and bus keys)"
        )
    return None


def identity_problem(value: object, what: str = "identity") -> str | None:
    """Why ``value`` cannot be an identity name, or None."""
    if not isinstance(value, str):
        return f"{what} must be text, got {type(value).__name__}"
    if IDENTITY_RE.fullmatch(value) is None:
        return (
            f"{what} {value[:80]!r} must be 1-32 lowercase letters, digits, '_' or '-', starting with a "
            "letter (it becomes a file name and a certificate's common name)"
        )
    return None


def check_identifier(value: object, what: str = "name") -> str:
    """``value`` if it is a valid identifier.

    Raises:
        ValueError: naming ``what`` and the rule.
    """
    problem = identifier_problem(value, what)
    if problem is not None:
        raise ValueError(problem)
    assert isinstance(value, str)
    return value
