"""Zenoh's TLS, authentication and access control, built from the service's settings.

Without any of them (the default) the service's Zenoh session is open: whoever reaches its
endpoint may publish frames for any camera, read every camera's tracks and declare the liveliness
token that puts a camera on standby. With them, every session goes through one place where the
rules are enforced: the service's hub session becomes a Zenoh *router* and everything else
(stream workers, cameras, subscribers) connects to it as a *client* (docs/architecture.md §7). In
peer mode two peers could meet directly and bypass the hub's rules; through a router they cannot.
When the service itself is a client of a separate router (the compose file's), that router
enforces the same rules, which ``vtrack zenoh router-config`` writes from the same settings.

The rules (Zenoh's ``access_control``, deny by default) grant, under ``<prefix>``:

- the service's principal: everything (its workers publish tracks and declare tracker tokens);
- a camera's principal: publishing ``cameras/<camera>/frames`` and ``.../detections`` for the
  cameras named for it, and watching their trackers' liveliness tokens;
- a reader's principal: subscribing to ``cameras/<camera>/tracks`` (and what is below it)
  and ``cameras/<camera>/events``,
  querying ``tracks/current``, and watching the trackers' tokens of the cameras named for it.

A principal is a user name of Zenoh's user/password authentication, or, with mutual TLS and no
users file, the common name of the certificate a session presents.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import zenoh

from api_schemas.streams import CAMERA_PATTERN

ALL_CAMERAS = "*"
"""In a principal's list of cameras: every camera (a gateway's or a dashboard's right)."""

_EVERY_MESSAGE = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)


@dataclass(frozen=True, slots=True)
class TlsFiles:
    """The PEM files of Zenoh's TLS links (``tls/<host>:<port>`` endpoints).

    Attributes
    ----------
    certificate, private_key:
        What the hub presents to those who connect, and, with ``client_auth``, what the
        service's own clients (stream workers) present to the hub.
    root_ca:
        The certificate authority that signed the other side's certificate.
    client_auth:
        Mutual TLS: the hub accepts only clients with a certificate the root CA signed.
    """

    certificate: Path | None = None
    private_key: Path | None = None
    root_ca: Path | None = None
    client_auth: bool = False

    def link_config(self, *, listening: bool) -> dict[str, object]:
        """Zenoh's ``transport/link/tls`` section for a listening (hub) or connecting session."""
        section: dict[str, object] = {}
        if self.root_ca is not None:
            section["root_ca_certificate"] = str(self.root_ca)
        if self.certificate is not None and self.private_key is not None:
            if listening:
                section["listen_certificate"] = str(self.certificate)
                section["listen_private_key"] = str(self.private_key)
            elif self.client_auth:
                section["connect_certificate"] = str(self.certificate)
                section["connect_private_key"] = str(self.private_key)
        if self.client_auth:
            section["enable_mtls"] = True
        return section


@dataclass(frozen=True, slots=True)
class AccessRules:
    """Who may do what on the Zenoh keys of this service (see the module's docstring).

    ``cameras`` and ``readers`` map a principal to the cameras it publishes or reads
    (:data:`ALL_CAMERAS` for every one); tuples of pairs keep the options hashable and picklable.
    """

    prefix: str
    service: str
    cameras: tuple[tuple[str, tuple[str, ...]], ...] = ()
    readers: tuple[tuple[str, tuple[str, ...]], ...] = ()
    principal: Literal["usernames", "cert_common_names"] = "usernames"

    @classmethod
    def from_maps(
        cls,
        prefix: str,
        service: str,
        cameras: Mapping[str, list[str]],
        readers: Mapping[str, list[str]],
        principal: Literal["usernames", "cert_common_names"] = "usernames",
    ) -> AccessRules:
        def frozen(rights: Mapping[str, list[str]]) -> tuple[tuple[str, tuple[str, ...]], ...]:
            return tuple((who, tuple(names)) for who, names in sorted(rights.items()))

        return cls(prefix, service, frozen(cameras), frozen(readers), principal)

    def access_control(self) -> dict[str, object]:
        """Zenoh's ``access_control`` section: deny by default, allow what the rights grant."""
        p = self.prefix
        rules: list[dict[str, object]] = [
            _rule("service", _EVERY_MESSAGE, ("ingress", "egress"), [f"{p}/**"]),
        ]
        subjects: list[dict[str, object]] = [{"id": "service", self.principal: [self.service]}]
        policies: list[dict[str, object]] = [{"rules": ["service"], "subjects": ["service"]}]
        for role, rights in (("camera", self.cameras), ("reader", self.readers)):
            for index, (who, names) in enumerate(rights):
                subject = f"{role} {index}"
                subjects.append({"id": subject, self.principal: [who]})
                ids = []
                for kind, messages, flows, keys in _grants(role, p, names):
                    ids.append(f"{subject} {kind}")
                    rules.append(_rule(ids[-1], messages, flows, keys))
                policies.append({"rules": ids, "subjects": [subject]})
        return {
            "enabled": True,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        }

    def summary(self) -> str:
        """One line for the service's start: who may publish and read which cameras."""

        def listed(rights: tuple[tuple[str, tuple[str, ...]], ...]) -> str:
            return "; ".join(f"{who}: {', '.join(names)}" for who, names in rights) or "nobody"

        return (
            f"cameras publish as {listed(self.cameras)}; tracks are read by {listed(self.readers)}"
        )


def _rule(
    rule_id: str, messages: tuple[str, ...], flows: tuple[str, ...], keys: list[str]
) -> dict[str, object]:
    return {
        "id": rule_id,
        "permission": "allow",
        "messages": list(messages),
        "flows": list(flows),
        "key_exprs": keys,
    }


def _grants(
    role: str, prefix: str, cameras: tuple[str, ...]
) -> list[tuple[str, tuple[str, ...], tuple[str, ...], list[str]]]:
    """(kind, messages, flows, keys) a camera's or a reader's principal is allowed.

    Flows are the hub's: *ingress* is what the principal sends, *egress* what it is sent.
    """
    base = [f"{prefix}/cameras/{camera}" for camera in cameras]
    trackers = [f"{prefix}/trackers/{camera}/*" for camera in cameras]
    watch = [
        ("watch", ("declare_liveliness_subscriber", "liveliness_query"), ("ingress",), trackers),
        ("tokens", ("liveliness_token", "reply"), ("egress",), trackers),
    ]
    if role == "camera":
        published = [f"{b}/{what}" for b in base for what in ("frames", "detections")]
        return [
            ("publish", ("put", "delete"), ("ingress",), published),
            # a publisher learns of its subscribers (`vtrack publish --wait-for-subscriber`)
            ("matching", ("declare_subscriber",), ("egress",), published),
            *watch,
        ]
    # "tracks/**": the tracks, their end, and what is below (a subscriber of both declares it);
    # "events": what people did at the camera's zones and lines
    tracks = [f"{b}/{what}" for b in base for what in ("tracks/**", "events")]
    current = [f"{b}/tracks/current" for b in base]
    return [
        ("subscribe", ("declare_subscriber",), ("ingress",), tracks),
        ("receive", ("put", "delete"), ("egress",), tracks),
        ("query", ("query",), ("ingress",), current),
        ("answer", ("reply", "declare_queryable"), ("egress",), current),
        *watch,
    ]


@dataclass(frozen=True, slots=True)
class ZenohSecurity:
    """TLS, credentials and access rules of the service's Zenoh sessions (picklable).

    Attributes
    ----------
    tls:
        The PEM files of TLS endpoints.
    user, password:
        The credentials this service's sessions present (user/password authentication).
    users_file:
        ``user:password`` lines: whom the hub accepts (Zenoh's ``dictionary_file``).
    access:
        The rules the hub enforces, None for none.
    """

    tls: TlsFiles = field(default_factory=TlsFiles)
    user: str | None = None
    password: str | None = field(default=None, repr=False)
    users_file: Path | None = None
    access: AccessRules | None = None

    @property
    def enforced(self) -> bool:
        """Whether whoever connects must authenticate (and the hub is a router)."""
        return self.users_file is not None or self.tls.client_auth or self.access is not None

    @property
    def configured(self) -> bool:
        """Whether any of TLS, credentials or rules is set (the sessions go through a router)."""
        return (
            self.enforced
            or self.user is not None
            or any((self.tls.certificate, self.tls.private_key, self.tls.root_ca))
        )

    def apply(self, config: zenoh.Config, *, hub: bool) -> None:
        """Write the TLS, authentication and access-control sections into ``config``."""
        if section := self.tls.link_config(listening=hub):
            config.insert_json5("transport/link/tls", json.dumps(section))
        credentials: dict[str, str] = {}
        if self.user is not None and self.password is not None:
            credentials |= {"user": self.user, "password": self.password}
        if hub and self.users_file is not None:
            credentials["dictionary_file"] = str(self.users_file)
        if credentials:
            config.insert_json5("transport/auth/usrpwd", json.dumps(credentials))
        if hub and self.access is not None:
            config.insert_json5("access_control", json.dumps(self.access.access_control()))


def router_config(
    security: ZenohSecurity, listen: list[str], max_message_size: int | None = None
) -> dict[str, object]:
    """A ``zenohd`` configuration that enforces the service's rules (the compose file's router):
    the hub's sections, in router mode, listening on ``listen``."""
    config: dict[str, object] = {
        "mode": "router",
        "listen": {"endpoints": listen},
        "scouting": {"multicast": {"enabled": False}},
    }
    transport: dict[str, object] = {}
    if section := security.tls.link_config(listening=True):
        transport["link"] = {"tls": section}
    if security.users_file is not None:
        transport["auth"] = {"usrpwd": {"dictionary_file": str(security.users_file)}}
    if max_message_size is not None:
        transport.setdefault("link", {})["rx"] = {"max_message_size": max_message_size}  # type: ignore[index]
    if transport:
        config["transport"] = transport
    if security.access is not None:
        config["access_control"] = security.access.access_control()
    return config


def build_security(
    *,
    prefix: str,
    tls: TlsFiles,
    user: str | None,
    password: str | None,
    users_file: Path | None,
    cameras: Mapping[str, list[str]],
    readers: Mapping[str, list[str]],
    listen: list[str],
) -> ZenohSecurity:
    """The service's :class:`ZenohSecurity` from its settings; ValueError naming the
    ``VTRACK_ZENOH_*`` variables of a combination that cannot work."""
    if (tls.certificate is None) != (tls.private_key is None):
        raise ValueError(
            "VTRACK_ZENOH_TLS_CERTIFICATE and VTRACK_ZENOH_TLS_PRIVATE_KEY go together"
        )
    if tls.client_auth and None in (tls.certificate, tls.root_ca):
        raise ValueError(
            "VTRACK_ZENOH_TLS_CLIENT_AUTH needs VTRACK_ZENOH_TLS_CERTIFICATE, "
            "VTRACK_ZENOH_TLS_PRIVATE_KEY and VTRACK_ZENOH_TLS_ROOT_CA"
        )
    if tls.certificate is None and (secured := [e for e in listen if e.startswith("tls/")]):
        raise ValueError(
            f"VTRACK_ZENOH_LISTEN: {secured[0]} needs VTRACK_ZENOH_TLS_CERTIFICATE and "
            "VTRACK_ZENOH_TLS_PRIVATE_KEY"
        )
    if (user is None) != (password is None):
        raise ValueError("VTRACK_ZENOH_USER and VTRACK_ZENOH_PASSWORD go together")
    if users_file is not None:
        accepted = read_users_file(users_file)
        if user is None:
            raise ValueError(
                "VTRACK_ZENOH_USERS_FILE needs VTRACK_ZENOH_USER and VTRACK_ZENOH_PASSWORD: "
                "the service's stream workers authenticate to it as everyone else does"
            )
        if accepted.get(user) != password:
            raise ValueError(
                f"VTRACK_ZENOH_USER {user!r} with VTRACK_ZENOH_PASSWORD is not a line of "
                f"VTRACK_ZENOH_USERS_FILE ({users_file}): the stream workers could not connect"
            )
    for setting, rights in (("VTRACK_ZENOH_CAMERAS", cameras), ("VTRACK_ZENOH_READERS", readers)):
        for who, names in rights.items():
            bad = [n for n in names if n != ALL_CAMERAS and not re.match(CAMERA_PATTERN, n)]
            if not who or bad or not names:
                raise ValueError(
                    f"{setting}: {who!r}: give a principal and a list of camera names "
                    f'(letters, digits, "_", "." and "-") or "*", e.g. {{"gate-cam": ["gate"]}}'
                )
    access = None
    if users_file is not None or tls.client_auth:
        principal: Literal["usernames", "cert_common_names"]
        if users_file is not None:
            assert user is not None, "a users file goes with the service's user (checked above)"
            service, principal = user, "usernames"
        else:
            service = certificate_common_name(tls.certificate)
            principal = "cert_common_names"
        access = AccessRules.from_maps(prefix, service, cameras, readers, principal)
    elif cameras or readers:
        raise ValueError(
            "VTRACK_ZENOH_CAMERAS and VTRACK_ZENOH_READERS grant rights to authenticated "
            "principals: give VTRACK_ZENOH_USERS_FILE or VTRACK_ZENOH_TLS_CLIENT_AUTH"
        )
    return ZenohSecurity(tls, user, password, users_file, access)


def read_users_file(path: Path) -> dict[str, str]:
    """``user:password`` lines (Zenoh's dictionary file) as a dict; ValueError for a line
    that is not one."""
    users = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        name, colon, secret = line.partition(":")
        if not line.strip():
            continue
        if not (name and colon and secret):
            raise ValueError(
                f"VTRACK_ZENOH_USERS_FILE: line {number} of {path} is not user:password"
            )
        users[name] = secret
    return users


def certificate_common_name(path: Path | None) -> str:
    """The subject's common name of a PEM certificate (the principal it authenticates)."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    assert path is not None
    try:
        certificate = x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        raise ValueError(f"VTRACK_ZENOH_TLS_CERTIFICATE: {path} is not a PEM certificate") from None
    names = certificate.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not names:
        raise ValueError(f"VTRACK_ZENOH_TLS_CERTIFICATE: {path} has no common name")
    return str(names[0].value)
