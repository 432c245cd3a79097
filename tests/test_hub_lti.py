"""LTI 1.3 login on the class hub's configuration, for real: JupyterHub started with the
course's ``configure`` and an LTI settings file, a stand-in LMS on 127.0.0.1
(``lti_platform``: its keys served as JWKS, its authorisation end-point answering with a
signed ``id_token``) and each launch driven as a browser follows it: the LMS's login
initiation at the hub, the hub's redirect to the LMS, the LMS's form posted back.

Students the class file lists log in as the user the roster gives; a token for another
course or deployment, an expired token, a token signed by a key the LMS does not publish, a
student not in the class and an instructor without the Instructor role are refused. The
hub runs no proxy here (its REST API is answered by a stand-in): the login is the hub's own
pages, reached on its own port.
"""
from __future__ import annotations

import http.cookiejar
import json
import os
import re
import secrets
import subprocess
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
from http.server import BaseHTTPRequestHandler
from pathlib import Path

import pytest

pytest.importorskip("jupyterhub", reason="the class hub's packages (environment-hub.txt) "
                    "are not installed")
pytest.importorskip("ltiauthenticator", reason="jupyterhub-ltiauthenticator "
                    "(environment-hub.txt) is not installed")

from loopback import Loopback  # noqa: E402
from lti_platform import INSTRUCTOR, Launch, Platform  # noqa: E402

from annslam_lib.course.hub import HubError, HubLayout, lti  # noqa: E402
from annslam_lib.course.hub.client import free_ports  # noqa: E402

CONFIG = """
from annslam_lib.course.hub.config import check_spawner, configure
c = get_config()  # noqa: F821
configure(c)
c.ConfigurableHTTPProxy.should_start = False
c.ConfigurableHTTPProxy.api_url = {proxy!r}
check_spawner(c)
"""


class _ProxyAPI(BaseHTTPRequestHandler):
    """configurable-http-proxy's REST API, answered and forgotten."""

    def log_message(self, *args):
        pass

    def _answer(self, status, body=b""):
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):
        self._answer(200, b"{}")

    def do_POST(self):
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        self._answer(201)

    def do_DELETE(self):
        self._answer(204)


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args):
        return None


def _browser():
    jar = http.cookiejar.CookieJar()
    return urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar), _NoRedirect())


def _open(opener, url, form=None):
    """``(status, headers, text)`` of one request; redirects are not followed."""
    data = None if form is None else urllib.parse.urlencode(form).encode()
    try:
        with opener.open(url, data=data, timeout=30) as r:
            return r.status, r.headers, r.read().decode(errors="replace")
    except urllib.error.HTTPError as e:
        return e.code, e.headers, e.read().decode(errors="replace")


@pytest.fixture(scope="module")
def lti_hub(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lti")
    layout = HubLayout(tmp / "hub")
    for folder in (layout.state, layout.course):
        folder.mkdir(parents=True)
    (layout.course / "roster.csv").write_text(
        "username,name,lms_id,sis_id,email,section\n"
        "alice,Alice,,,Alice@Uni.example,A\n"
        "bob,Bob,,,bob@uni.example,A\n")
    class_file = tmp / "class.txt"
    class_file.write_text("alice\nbob\n")
    port = free_ports()
    token = secrets.token_hex(24)
    with Platform() as platform, Loopback(_ProxyAPI) as proxy:
        settings = tmp / "lti.toml"
        settings.write_text(platform.settings())
        (tmp / "jupyterhub_config.py").write_text(
            CONFIG.format(proxy=proxy.url))
        env = {**os.environ, "ANNSLAM_HUB_DIR": str(layout.root),
               "ANNSLAM_HUB_CLASS": str(class_file), "ANNSLAM_HUB_LTI": str(settings),
               "ANNSLAM_HUB_PORT": str(port), "ANNSLAM_HUB_ADMIN_TOKEN": token,
               "ANNSLAM_HUB_INSTRUCTOR": "teacher",
               "CONFIGPROXY_AUTH_TOKEN": secrets.token_hex(16),
               "PYTHONPATH": str(Path(__file__).resolve().parents[1])}   # this checkout's library
        log = tmp / "hub.log"
        exe = Path(sys.executable).parent / "jupyterhub"
        with open(log, "wb") as fh:
            proc = subprocess.Popen([str(exe), "-f", str(tmp / "jupyterhub_config.py")],
                                    cwd=layout.state, env=env, stdout=fh,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        hub = f"http://127.0.0.1:{port + 1}"
        try:
            end = time.monotonic() + 60
            while True:
                assert proc.poll() is None, log.read_text()[-3000:]
                assert time.monotonic() < end, log.read_text()[-3000:]
                try:
                    with urllib.request.urlopen(hub + "/hub/api", timeout=3):
                        break
                except OSError:
                    time.sleep(0.3)
            yield platform, hub, token, log
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()


def _launch(platform: Platform, hub: str, launch: Launch):
    """One launch from the LMS, as a browser follows it; ``(status of the hub's answer to
    the posted token, the opener with the browser's cookies, the answer's text)``."""
    hint = secrets.token_hex(8)
    platform.launches[hint] = launch
    browser = _browser()
    status, headers, text = _open(browser, hub + "/hub/lti13/oauth_login", {
        "iss": platform.url, "login_hint": hint, "client_id": platform.client_id,
        "lti_deployment_id": platform.deployment, "target_link_uri": hub + "/hub/home"})
    assert status == 302, (status, text[-500:])
    assert headers["Location"].startswith(platform.url + "/authorize?")
    status, _, form = _open(browser, headers["Location"])
    assert status == 200, form
    action = html_value(form, r'action="([^"]+)"')
    fields = dict(re.findall(r'name="(\w+)" value="([^"]*)"', form))
    status, headers, text = _open(browser, action, fields)
    return status, browser, text


def html_value(text, pattern):
    import html

    return html.unescape(re.search(pattern, text).group(1))


def _logged_in_as(hub: str, browser) -> str | None:
    status, _, text = _open(browser, hub + "/hub/home")
    if status != 200:
        return None
    found = re.search(r'data-user="([^"]+)"', text) or re.search(r"user=([a-z][\w-]*)", text)
    return found.group(1) if found else text


def test_a_student_of_the_class_arrives_from_the_lms_logged_in_as_the_roster_names_them(lti_hub):
    platform, hub, token, log = lti_hub
    status, browser, text = _launch(platform, hub, Launch("alice@uni.example"))
    assert status == 302, (status, text[-800:])
    status, _, page = _open(browser, hub + "/hub/home")
    assert status == 200 and "alice" in page, page[-500:]
    req = urllib.request.Request(hub + "/hub/api/users/alice",
                                 headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(req, timeout=10) as r:
        user = json.loads(r.read())
    assert user["name"] == "alice" and not user["admin"]
    # a fresh browser with no launch is not logged in
    status, headers, _ = _open(_browser(), hub + "/hub/home")
    assert status == 302 and "/hub/login" in headers["Location"]


@pytest.mark.parametrize("launch, status, words", [
    (Launch("bob@uni.example", context="course-2026"), 403, "another course"),
    (Launch("bob@uni.example", deployment="deployment-9"), 403, "another deployment"),
    (Launch("bob@uni.example", age=900, lifetime=300), 400, "expired"),
    (Launch("bob@uni.example", foreign_key=True), 400, "Signature verification failed"),
    (Launch("mallory@uni.example"), 403, "did not name you"),
    (Launch("carol"), 403, "User missing or null"),
    (Launch("teacher", roles=()), 403, "Instructor role"),
], ids=["other-course", "other-deployment", "expired", "bad-signature", "not-a-name",
        "not-in-class", "instructor-without-role"])
def test_the_hub_refuses_a_launch_it_must_not_trust(lti_hub, launch, status, words):
    platform, hub, _, _ = lti_hub
    got, browser, text = _launch(platform, hub, launch)
    assert got == status, (got, text[-800:])
    assert words in text, text[-800:]
    assert _open(browser, hub + "/hub/home")[0] == 302       # not logged in


def test_no_login_without_the_lms_token(lti_hub):
    """JupyterHub hands its login form's fields and the token API's "auth" body to the
    authenticator too: a forged set of claims there logs nobody in and makes no token."""
    platform, hub, token, _ = lti_hub
    forged = {"https://purl.imsglobal.org/spec/lti/claim/deployment_id": platform.deployment,
              "https://purl.imsglobal.org/spec/lti/claim/context": {"id": platform.course},
              "https://purl.imsglobal.org/spec/lti/claim/roles": [INSTRUCTOR],
              "email": "teacher"}
    for name in ("alice", "teacher"):
        req = urllib.request.Request(hub + f"/hub/api/users/{name}/tokens",
                                     data=json.dumps({"auth": forged}).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=10) as r:
                status = r.status
        except urllib.error.HTTPError as e:
            status = e.code
        assert status == 403, (name, status)
    browser = _browser()
    _open(browser, hub + "/hub/login")
    status, _, _ = _open(browser, hub + "/hub/login", {"email": "alice@uni.example",
                                                       "username": "alice"})
    assert status != 302 and _open(browser, hub + "/hub/home")[0] == 302


def test_the_instructor_arrives_with_the_lms_instructor_role(lti_hub):
    platform, hub, token, _ = lti_hub
    status, browser, text = _launch(platform, hub, Launch("teacher", roles=(INSTRUCTOR,)))
    assert status == 302, (status, text[-800:])
    req = urllib.request.Request(hub + "/hub/api/users/teacher",
                                 headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(req, timeout=10) as r:
        assert json.loads(r.read())["admin"] is True


def test_the_idle_culler_runs_as_a_service_of_the_hub(lti_hub):
    _, hub, token, log = lti_hub
    req = urllib.request.Request(hub + "/hub/api/services/idle-culler",
                                 headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(req, timeout=10) as r:
        service = json.loads(r.read())
    assert service["command"][-2:] == ["--timeout=3600", "--cull-every=300"]
    assert service["pid"] > 0
    os.kill(service["pid"], 0)                        # alive


@pytest.mark.parametrize("text, words", [
    ("", "missing or empty"),
    ('issuer = "x"\n', "missing or empty"),
    ('colour = "red"\n', "unknown LTI setting"),
    ("issuer = ", "cannot read"),
])
def test_a_bad_settings_file_is_refused_with_its_reason(tmp_path, text, words):
    f = tmp_path / "lti.toml"
    f.write_text(text)
    with pytest.raises(HubError, match=words):
        lti.read_settings(f)


def test_an_lms_address_in_the_clear_is_refused(tmp_path):
    f = tmp_path / "lti.toml"
    with Platform() as p:
        f.write_text(p.settings().replace(p.url + "/jwks", "http://lms.example/jwks"))
    with pytest.raises(HubError, match="jwks_url .* must be an https"):
        lti.read_settings(f)
