"""A local certificate authority and the certificates of Zenoh's TLS links, for tests and small
sites (``vtrack zenoh certificates``); a site with its own PKI uses its own files instead.

Keys are ECDSA P-256, which rustls (Zenoh's TLS) takes; every certificate is good for both ends
of a link (server and client authentication) so that one file serves the hub and, under mutual
TLS, the service's own clients.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

CA_NAME = "ca"
"""``ca.pem`` and ``ca.key`` in the folder: the authority's certificate and key."""

CA_DAYS = 3650
LEAF_DAYS = 825
"""The longest validity browsers and most TLS stacks accept for a leaf certificate."""


@dataclass(frozen=True, slots=True)
class Issued:
    """A certificate written (or found) in the folder."""

    name: str
    certificate: Path
    private_key: Path
    created: bool


def make_certificates(
    folder: Path, names: dict[str, list[str]], *, authority: str = "vtrack local CA"
) -> list[Issued]:
    """The CA of ``folder`` (made when it has none) and a certificate for each of ``names``.

    ``names`` maps a common name (a principal: the service, a camera, a reader) to the host
    names and IP addresses it is reached at (its subject alternative names; none for a
    client-only certificate). Files already there are kept, so that running the command again
    for a new camera does not replace the certificates given out before.
    """
    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    ca_key_path, ca_path = folder / f"{CA_NAME}.key", folder / f"{CA_NAME}.pem"
    if ca_path.exists() and ca_key_path.exists():
        ca = x509.load_pem_x509_certificate(ca_path.read_bytes())
        ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), password=None)
        issued = [Issued(CA_NAME, ca_path, ca_key_path, False)]
    else:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, authority)])
        usage = x509.KeyUsage(
            digital_signature=True,
            key_cert_sign=True,
            crl_sign=True,
            content_commitment=False,
            key_encipherment=False,
            data_encipherment=False,
            key_agreement=False,
            encipher_only=False,
            decipher_only=False,
        )
        ca = (
            _builder(subject, subject, ca_key.public_key(), now, CA_DAYS)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(usage, critical=True)
            .add_extension(
                x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False
            )
            .sign(ca_key, hashes.SHA256())
        )
        _write(ca_path, ca_key_path, ca, ca_key)
        issued = [Issued(CA_NAME, ca_path, ca_key_path, True)]
    assert isinstance(ca_key, ec.EllipticCurvePrivateKey)
    for name, hosts in names.items():
        path, key_path = folder / f"{name}.pem", folder / f"{name}.key"
        if path.exists() and key_path.exists():
            issued.append(Issued(name, path, key_path, False))
            continue
        key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        builder = (
            _builder(subject, ca.subject, key.public_key(), now, LEAF_DAYS)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
            .add_extension(
                x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                critical=False,
            )
        )
        if hosts:
            builder = builder.add_extension(
                x509.SubjectAlternativeName([_alternative_name(h) for h in hosts]), critical=False
            )
        _write(path, key_path, builder.sign(ca_key, hashes.SHA256()), key)
        issued.append(Issued(name, path, key_path, True))
    return issued


def _builder(
    subject: x509.Name, issuer: x509.Name, public_key, now: datetime.datetime, days: int
) -> x509.CertificateBuilder:
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer)
        .public_key(public_key)
        .serial_number(x509.random_serial_number())
        # a few minutes back: clocks of cameras and servers are rarely in step
        .not_valid_before(now - datetime.timedelta(minutes=10))
        .not_valid_after(now + datetime.timedelta(days=days))
    )


def _alternative_name(host: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(host.strip("[]")))
    except ValueError:
        return x509.DNSName(host)


def _write(path: Path, key_path: Path, certificate: x509.Certificate, key) -> None:
    path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    # the key readable by its owner only, from its first byte
    descriptor = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as file:
        file.write(
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.PKCS8,
                serialization.NoEncryption(),
            )
        )
