"""The link's key material: a small CA, and one certificate and private key per host, signed by it.

Each host's certificate names the host (its common name, which the other hosts' access rules
match) and the addresses it is reached at (what a connecting host checks against the endpoint it
dialled). Files are written atomically and readable by their owner only (0600); an existing file
is never replaced unless asked. `problems` says what is wrong with a host's files, for `validate`
and for the bridge's pre-flight check (docs/security.md).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

CA_NAME = "ca"
VALID_DAYS = 365
WARN_DAYS = 30  # `validate` and `hosts keys` say when a certificate ends within this many days
LOOPBACK = ("localhost", "127.0.0.1", "::1")


@dataclass(frozen=True)
class HostFiles:
    """Where one host's credentials lie in a key directory."""

    ca: Path
    certificate: Path
    key: Path | None


def files(directory: Path, host: str) -> HostFiles:
    return HostFiles(directory / f"{CA_NAME}.pem", directory / f"{host}.pem", directory / f"{host}.key")


def endpoint_address(endpoint: str) -> str:
    """'tls/10.0.0.1:7447' -> '10.0.0.1'; '[::1]' brackets dropped."""
    address = endpoint.split("/", 1)[1].rsplit(":", 1)[0]
    return address.strip("[]")


def _write(path: Path, data: bytes, force: bool) -> None:
    """All or nothing, owner-only; an existing file stays unless `force`."""
    if path.exists() and not force:
        raise FileExistsError(f"{path} exists (--force replaces it)")
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, "wb") as out:
            out.write(data)
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _pem_key(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _subject_alt_names(names: list[str]) -> x509.SubjectAlternativeName:
    entries: list[x509.GeneralName] = []
    for name in dict.fromkeys(names):
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            entries.append(x509.DNSName(name))
    return x509.SubjectAlternativeName(entries)


def make_ca(directory: Path, system: str, days: int = VALID_DAYS, force: bool = False) -> None:
    """A CA for this system's hosts: `ca.pem` (every host's trust) and `ca.key` (keep it off the hosts)."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"hapticop {system} CA")])
    now = dt.datetime.now(dt.UTC)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False),
                           critical=True)
            .sign(key, hashes.SHA256()))
    _write(directory / f"{CA_NAME}.key", _pem_key(key), force)
    _write(directory / f"{CA_NAME}.pem", cert.public_bytes(serialization.Encoding.PEM), force)


def make_host(directory: Path, host: str, addresses: list[str], days: float = VALID_DAYS, force: bool = False,
              start: dt.datetime | None = None) -> None:
    """`HOST.pem` and `HOST.key`: the host's name as common name and SAN, with the addresses it is reached at,
    valid for `days` from `start` (default: now)."""
    ca_key = serialization.load_pem_private_key((directory / f"{CA_NAME}.key").read_bytes(), None)
    ca = x509.load_pem_x509_certificate((directory / f"{CA_NAME}.pem").read_bytes())
    key = ec.generate_private_key(ec.SECP256R1())
    now = start or dt.datetime.now(dt.UTC)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, host)]))
            .issuer_name(ca.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5)).not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(_subject_alt_names([host, *addresses, *LOOPBACK]), critical=False)
            .add_extension(x509.ExtendedKeyUsage([x509.oid.ExtendedKeyUsageOID.SERVER_AUTH,
                                                  x509.oid.ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
            .sign(ca_key, hashes.SHA256()))
    _write(directory / f"{host}.key", _pem_key(key), force)
    _write(directory / f"{host}.pem", cert.public_bytes(serialization.Encoding.PEM), force)


def problems(directory: Path, host: str, addresses: list[str] = (), private: bool = True) -> list[tuple[str, str]]:
    """What keeps `host` from proving who it is with its files in `directory` (see `problems_of`)."""
    where = files(directory, host)
    return problems_of(where.ca, where.certificate, where.key if private else None, host, addresses)


def problems_of(ca_path: Path, cert_path: Path, key_path: Path | None, host: str,
                addresses: list[str] = ()) -> list[tuple[str, str]]:
    """What keeps `host` from proving who it is: (which file, what is wrong), empty when nothing.

    `key_path` None: the certificate alone (another host's, whose private key stays on that host)."""
    where = HostFiles(ca_path, cert_path, key_path)
    found: list[tuple[str, str]] = []
    now = dt.datetime.now(dt.UTC)
    ca = _certificate(where.ca, found)
    cert = _certificate(where.certificate, found)
    for path, loaded in ((where.ca, ca), (where.certificate, cert)):
        if loaded is not None and not loaded.not_valid_before_utc <= now <= loaded.not_valid_after_utc:
            found.append((str(path), f"expired on {loaded.not_valid_after_utc:%Y-%m-%d}"
                          if now > loaded.not_valid_after_utc else "not valid yet"))
    if cert is not None:
        names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
        common = names[0].value if names else None
        if common != host:
            found.append((str(where.certificate), f"is host '{common}''s certificate, not host '{host}''s"))
        elif ca is not None and cert.issuer != ca.subject:
            found.append((str(where.certificate), f"is not signed by {where.ca.name}"))
        elif ca is not None:
            try:
                cert.verify_directly_issued_by(ca)
            except Exception:  # noqa: BLE001 - any failure of the signature is the same finding
                found.append((str(where.certificate), f"is not signed by {where.ca.name}"))
        missing = _not_named(cert, addresses)
        if missing:
            found.append((str(where.certificate), f"does not name {', '.join(missing)}, where host '{host}' "
                          "is reached (the other hosts would refuse it)"))
    if where.key is not None:
        if not where.key.exists():
            found.append((str(where.key), "is missing"))
        else:
            mode = where.key.stat().st_mode & 0o777
            if mode & 0o077:
                found.append((str(where.key), f"is readable by others (mode {mode:o}): chmod 600"))
            elif cert is not None:
                try:
                    key = serialization.load_pem_private_key(where.key.read_bytes(), None)
                except (ValueError, TypeError):
                    found.append((str(where.key), "is not a PEM private key without a passphrase"))
                else:
                    if key.public_key().public_bytes(serialization.Encoding.DER,
                                                     serialization.PublicFormat.SubjectPublicKeyInfo) != \
                            cert.public_key().public_bytes(serialization.Encoding.DER,
                                                           serialization.PublicFormat.SubjectPublicKeyInfo):
                        found.append((str(where.key), f"does not belong to {where.certificate.name}"))
    return found


def expiry(*paths: Path) -> dt.datetime | None:
    """When the first of these certificates ends (a host's link is good only while its CA's and its own are);
    None when one cannot be read (`problems_of` says why)."""
    try:
        return min(x509.load_pem_x509_certificate(p.read_bytes()).not_valid_after_utc for p in paths)
    except (OSError, ValueError):
        return None


def ending_soon(directory: Path, host: str, days: float = WARN_DAYS) -> list[tuple[str, str]]:
    """(which file, when it ends) for `host`'s certificate and the CA's, when they end within `days` (still valid)."""
    now = dt.datetime.now(dt.UTC)
    found = []
    for path in (files(directory, host).ca, files(directory, host).certificate):
        end = expiry(path)
        if end is not None and now <= end < now + dt.timedelta(days=days):
            found.append((str(path), f"expires on {end:%Y-%m-%d %H:%M} UTC, within {days:g} days: the link will "
                          "stop then"))
    return found


def _certificate(path: Path, found: list[tuple[str, str]]) -> x509.Certificate | None:
    if not path.exists():
        found.append((str(path), "is missing"))
        return None
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        found.append((str(path), "is not a PEM certificate"))
        return None


def _not_named(cert: x509.Certificate, addresses: list[str]) -> list[str]:
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return list(addresses)
    named = {str(a) for a in san.get_values_for_type(x509.IPAddress)} | set(san.get_values_for_type(x509.DNSName))
    return [a for a in addresses if a not in named]
