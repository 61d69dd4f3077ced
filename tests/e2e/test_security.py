"""TLS and Zenoh access control through `--zenoh-config`, end to end; loopback by default.

The test makes its own certificate authority and server certificate with openssl.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import free_port, run_wallmap, wait_for_port

from wallmap.common.link_settings import DEFAULT_CONNECT
from wallmap.launcher import sample_bag

pytestmark = pytest.mark.e2e

ACL = """{
  access_control: {
    enabled: true,
    default_permission: "deny",
    rules: [{
      id: "wallmap-keys",
      messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                 "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"],
      flows: ["egress", "ingress"],
      permission: "allow",
      key_exprs: ["wallmap/**"],
    }],
    subjects: [{ id: "loopback", interfaces: ["lo"] }],
    policies: [{ rules: ["wallmap-keys"], subjects: ["loopback"] }],
  },
}"""


@pytest.fixture(scope="module")
def certificates(tmp_path_factory) -> Path:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: the test cannot make its certificates")
    folder = tmp_path_factory.mktemp("tls")

    def openssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)

    openssl(
        "req",
        "-x509",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-keyout",
        "ca.key",
        "-out",
        "ca.pem",
        "-days",
        "1",
        "-subj",
        "/CN=wallmap test CA",
    )
    openssl(
        "req",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-keyout",
        "server.key",
        "-out",
        "server.csr",
        "-subj",
        "/CN=localhost",
    )
    (folder / "san.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    openssl(
        "x509",
        "-req",
        "-in",
        "server.csr",
        "-CA",
        "ca.pem",
        "-CAkey",
        "ca.key",
        "-CAcreateserial",
        "-out",
        "server.pem",
        "-days",
        "1",
        "-extfile",
        "san.cnf",
    )
    tls = "transport: { link: { tls: { %s } } }"
    (folder / "router.json5").write_text(
        "{" + tls % f'listen_private_key: "{folder}/server.key", '
        f'listen_certificate: "{folder}/server.pem"' + "}"
    )
    (folder / "client.json5").write_text(
        "{" + tls % f'root_ca_certificate: "{folder}/ca.pem"' + "}"
    )
    return folder


def _services(stack, *args: str) -> None:
    for service in ("mapper", "detector"):
        stack.start(f"{service}{len(stack.services)}", service, *args)


def test_tls_end_to_end(stack, certificates) -> None:
    port = free_port()
    client = ["--connect", f"tls/localhost:{port}", "--prefix", stack.prefix]
    client += ["--zenoh-config", str(certificates / "client.json5")]
    stack.start(
        "tls-router",
        "router",
        "--listen",
        f"tls/127.0.0.1:{port}",
        "--zenoh-config",
        str(certificates / "router.json5"),
    )
    wait_for_port(port)
    _services(stack, *client)
    played = stack.run("player", str(sample_bag()), "--fast", *client)
    assert played.returncode == 0, played.stderr
    assert "the mapper integrated 245" in played.stdout
    mapped = stack.run("query", "--min-obs", "3", *client, timeout=30)
    assert mapped.returncode == 0, mapped.stderr
    assert " walls from 245 frames" in mapped.stdout
    # Without the CA the client does not trust the router: one line, exit 1.
    plain = run_wallmap("query", "--connect", f"tls/localhost:{port}", timeout=60, expect=1)
    assert plain.stderr.startswith("wallmap query: error: cannot reach a Zenoh router")
    assert len(plain.stderr.strip().splitlines()) == 1


def test_access_control_lets_wallmap_keys_through_and_nothing_else(stack, tmp_path) -> None:
    config = tmp_path / "acl.json5"
    config.write_text(ACL)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = stack.start(
        "acl-router", "router", "--listen", endpoint, "--zenoh-config", str(config)
    )
    router.zenoh_errors = True  # it logs each refused declaration that a client later undeclares
    wait_for_port(port)
    _services(stack, "--connect", endpoint)  # prefix wallmap: allowed
    played = stack.run("player", str(sample_bag()), "--fast", "--connect", endpoint)
    assert played.returncode == 0, played.stderr
    _services(stack, "--connect", endpoint, "--prefix", "other")  # everything else: denied
    denied = stack.run(
        "player",
        str(sample_bag()),
        "--fast",
        "--connect",
        endpoint,
        "--prefix",
        "other",
        "--wait-timeout",
        "3",
        expect=1,
    )
    assert "no detector and no mapper running under prefix 'other'" in denied.stderr


def test_the_router_listens_on_loopback_unless_told_otherwise() -> None:
    assert DEFAULT_CONNECT == "tcp/127.0.0.1:7447"
    out = run_wallmap("router", "--help", timeout=30)
    assert f"default {DEFAULT_CONNECT}" in out.stdout
