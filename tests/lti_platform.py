"""A stand-in LTI 1.3 platform (an LMS) on 127.0.0.1, for the hub's LTI login tests.

It serves its public key set (``/jwks``) and an OIDC authorisation end-point
(``/authorize``) that answers a tool's authentication request as an LMS does: an HTML form
posting a signed ``id_token`` and the tool's ``state`` to the tool's ``redirect_uri``. What
the token says is chosen per launch by the opaque ``login_hint`` (``Launch`` objects kept by
name), so one platform serves every case of a test: another course, an expired token, a
signature by a key not in the set.
"""
from __future__ import annotations

import html
import json
import time
import urllib.parse
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler

import jwt
from cryptography.hazmat.primitives.asymmetric import rsa
from loopback import Loopback

CLAIM = "https://purl.imsglobal.org/spec/lti/claim/"
LEARNER = "http://purl.imsglobal.org/vocab/lis/v2/membership#Learner"
INSTRUCTOR = "http://purl.imsglobal.org/vocab/lis/v2/membership#Instructor"


@dataclass
class Launch:
    """One user's launch: who they are and what goes wrong with the token, if anything."""
    email: str
    roles: tuple = (LEARNER,)
    context: str | None = None        # None: the platform's course
    deployment: str | None = None     # None: the platform's deployment
    age: float = 0.0                  # seconds since the token was issued
    lifetime: float = 300.0           # seconds it is valid from its issue
    foreign_key: bool = False         # signed by a key the JWKS does not hold
    extra: dict = field(default_factory=dict)


class Platform(Loopback):
    """The stand-in LMS; ``with Platform(...) as p``: serving on ``p.url``."""

    def __init__(self, client_id: str = "annslam-tool", course: str = "course-2027",
                 deployment: str = "deployment-1"):
        self.client_id, self.course, self.deployment = client_id, course, deployment
        self.key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
        self.other_key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
        self.kid = "platform-key-1"
        self.launches: dict[str, Launch] = {}
        super().__init__(self._handler())

    def settings(self, username_claim: str = "email") -> str:
        """The tool's LTI settings file for this platform (TOML)."""
        return "\n".join([
            f'issuer = "{self.url}"', f'client_id = "{self.client_id}"',
            f'deployment_id = "{self.deployment}"', f'authorize_url = "{self.url}/authorize"',
            f'jwks_url = "{self.url}/jwks"', f'course = "{self.course}"',
            f'username_claim = "{username_claim}"', ""])

    def jwks(self) -> dict:
        public = json.loads(jwt.algorithms.RSAAlgorithm.to_jwk(self.key.public_key()))
        return {"keys": [{**public, "kid": self.kid, "alg": "RS256", "use": "sig"}]}

    def id_token(self, launch: Launch, nonce: str) -> str:
        now = time.time() - launch.age
        claims = {
            "iss": self.url, "aud": self.client_id, "sub": f"lms-{launch.email}",
            "iat": int(now), "exp": int(now + launch.lifetime), "nonce": nonce,
            "email": launch.email, "name": launch.email.split("@")[0].title(),
            CLAIM + "message_type": "LtiResourceLinkRequest",
            CLAIM + "version": "1.3.0",
            CLAIM + "deployment_id": launch.deployment or self.deployment,
            CLAIM + "target_link_uri": "",
            CLAIM + "resource_link": {"id": "link-1", "title": "annslam"},
            CLAIM + "context": {"id": launch.context or self.course, "label": "SLAM",
                                "title": "Robot mapping"},
            CLAIM + "roles": list(launch.roles),
            **launch.extra,
        }
        key = self.other_key if launch.foreign_key else self.key
        return jwt.encode(claims, key, algorithm="RS256", headers={"kid": self.kid})

    def _handler(self):
        platform = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _send(self, status: int, body: str, kind: str) -> None:
                data = body.encode()
                self.send_response(status)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def do_GET(self):
                url = urllib.parse.urlsplit(self.path)
                if url.path == "/jwks":
                    return self._send(200, json.dumps(platform.jwks()), "application/json")
                if url.path != "/authorize":
                    return self._send(404, "not found", "text/plain")
                q = dict(urllib.parse.parse_qsl(url.query))
                launch = platform.launches.get(q.get("login_hint", ""))
                if (launch is None or q.get("client_id") != platform.client_id
                        or q.get("response_type") != "id_token" or not q.get("nonce")):
                    return self._send(400, "bad authentication request", "text/plain")
                token = platform.id_token(launch, q["nonce"])
                form = (f'<form id="f" method="post" action="{html.escape(q["redirect_uri"])}">'
                        f'<input type="hidden" name="id_token" value="{token}">'
                        f'<input type="hidden" name="state" value="{html.escape(q["state"])}">'
                        '</form><script>document.getElementById("f").submit()</script>')
                return self._send(200, form, "text/html")

        return Handler
