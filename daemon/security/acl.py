"""Zenoh access-control rules from the rights of each service: default deny, each identity its own keys.

What each service publishes, subscribes to and declares is said once, in the rig's service table
(:mod:`flagtrack.daemon.rig.access` makes the :class:`Rights` of each from it, with the key
expressions of :class:`~flagtrack.daemon.schema.Keys`). A subject is a certificate common name (an
identity, see :mod:`.certs`).

How the rules act (Zenoh 1.x, checked by the tests): on the node that enforces them (the router;
every peer in peer mode), a message from an identity is ``ingress`` on the link from it, and a
message to it ``egress`` on the link to it. So

* to **publish** a key, an identity needs ``put`` ingress, and ``declare_subscriber`` egress (a
  Zenoh client sends a key's data only once it hears of a subscriber);
* to **subscribe**, ``declare_subscriber`` ingress and ``put`` egress;
* its **liveliness token** ``<ns>/alive/<service>``: ``liveliness_token`` ingress; watching the
  services' liveliness: ``declare_liveliness_subscriber`` and ``liveliness_query`` ingress,
  ``liveliness_token`` and ``reply`` egress, on ``<ns>/alive/**``.

Anything else (another service's key, a command from a viewer, a key of another namespace) is
denied. The router identity (``router``) may do everything in the namespace: in client mode it
carries every message to and from the services, and a second router joins as it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security.config import ROUTER, SecurityConfig


@dataclass(frozen=True)
class Rights:
    """What one identity may do: keys it publishes, keys it subscribes to, its liveliness tokens,
    whether it watches the services' liveliness."""

    publish: tuple[str, ...] = ()
    subscribe: tuple[str, ...] = ()
    tokens: tuple[str, ...] = ()
    watch: bool = False

    def __or__(self, other: Rights) -> Rights:
        return Rights(
            _unique(self.publish + other.publish),
            _unique(self.subscribe + other.subscribe),
            _unique(self.tokens + other.tokens),
            self.watch or other.watch,
        )


def _unique(items: Iterable[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(items))


def operator_rights(keys: Keys, name: str) -> Rights:
    """Operator ``name``'s rights beyond its services': send recorder and tunnel commands, ask for
    wind speeds on its own request key (so that key says who asks), read every key of the namespace,
    watch liveliness."""
    return Rights(
        publish=(keys.recorder_command(), keys.tunnel_command(), keys.speed_request(name)),
        subscribe=(f"{keys.namespace}/**",),
        watch=True,
    )


def identity_rights(keys: Keys, security: SecurityConfig, services: Mapping[str, Rights]) -> dict[str, Rights]:
    """Every identity the rules know and its rights, from the rights of each service (by name): each
    service's own name, the identities of ``security.identities`` (the union of their services'
    rights), the operators (their own services' rights, if any, and :func:`operator_rights`)."""
    names = [*services, *security.identities, *security.operators]
    rights: dict[str, Rights] = {}
    for name in dict.fromkeys(names):
        total = Rights()
        for role in security.identities.get(name, (name,) if name in services else ()):
            total = total | services[role]
        if name in security.operators:
            total = total | operator_rights(keys, name)
        rights[name] = total
    return rights


def _rule(rule_id: str, messages: list[str], flows: list[str], key_exprs: Iterable[str]) -> dict[str, Any]:
    return {"id": rule_id, "messages": messages, "flows": flows, "permission": "allow", "key_exprs": list(key_exprs)}


def _grants(keys: Keys, rights: Rights) -> list[tuple[str, list[str], list[str], Sequence[str]]]:
    """(rule suffix, messages, flows, key expressions) of ``rights`` (see the module docstring)."""
    alive = [keys.alive_all()] if rights.watch else []
    return [
        ("publish", ["put"], ["ingress"], rights.publish),
        ("publish-interest", ["declare_subscriber"], ["egress"], rights.publish),
        ("subscribe", ["declare_subscriber"], ["ingress"], rights.subscribe),
        ("receive", ["put"], ["egress"], rights.subscribe),
        ("token", ["liveliness_token"], ["ingress"], rights.tokens),
        ("watch", ["declare_liveliness_subscriber", "liveliness_query"], ["ingress"], alive),
        ("watch-receive", ["liveliness_token", "reply"], ["egress"], alive),
    ]


def access_control(keys: Keys, security: SecurityConfig, services: Mapping[str, Rights]) -> dict[str, Any]:
    """The Zenoh ``access_control`` section for the rights of each service (by name): enabled, default
    deny, one subject per identity (its certificate common name) with the rules of its rights (see the
    module docstring)."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for name, rights in identity_rights(keys, security, services).items():
        ids: list[str] = []
        for suffix, messages, flows, key_exprs in _grants(keys, rights):
            if key_exprs:
                rules.append(_rule(f"{name}-{suffix}", messages, flows, key_exprs))
                ids.append(f"{name}-{suffix}")
        if ids:
            subjects.append({"id": f"subject-{name}", "cert_common_names": [name]})
            policies.append({"id": f"policy-{name}", "rules": ids, "subjects": [f"subject-{name}"]})
    everything = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "reply",
        "declare_queryable",
        "liveliness_token",
        "liveliness_query",
        "declare_liveliness_subscriber",
    ]
    rules.append(_rule(f"{ROUTER}-all", everything, ["ingress", "egress"], [f"{keys.namespace}/**"]))
    subjects.append({"id": f"subject-{ROUTER}", "cert_common_names": [ROUTER]})
    policies.append({"id": f"policy-{ROUTER}", "rules": [f"{ROUTER}-all"], "subjects": [f"subject-{ROUTER}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def describe(control: Mapping[str, Any]) -> list[str]:
    """One line per policy: who may do what on which keys (for ``flagtrack router --print-rules``)."""
    by_id = {rule["id"]: rule for rule in control.get("rules", [])}
    names = {s["id"]: ",".join(s.get("cert_common_names", [])) for s in control.get("subjects", [])}
    lines = []
    for policy in control.get("policies", []):
        who = " ".join(names[s] for s in policy["subjects"])
        for rule_id in policy["rules"]:
            rule = by_id[rule_id]
            lines.append(f"{who}: {'/'.join(rule['messages'])} {'/'.join(rule['flows'])} {' '.join(rule['key_exprs'])}")
    return lines
