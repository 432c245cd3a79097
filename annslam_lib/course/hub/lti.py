"""Login from the learning-management system with LTI 1.3 (``./course.sh hub --lti FILE``).

The LMS (Canvas, Moodle, Blackboard, Open edX) is the LTI *platform*, the hub the *tool*. A
student who clicks the course's link in the LMS arrives at the hub already logged in: the
LMS starts an OpenID Connect login at the hub (``/hub/lti13/oauth_login``), the hub sends the
browser back to the LMS with a state and a nonce, and the LMS posts an ``id_token`` it signed
to ``/hub/lti13/oauth_callback``. ``jupyterhub-ltiauthenticator`` checks the token: the
signature against the LMS's published keys (JWKS), the issuer, the audience (the tool's
client id), its age, its expiry, the state and the nonce. :class:`CourseLTIAuthenticator`
adds what the course needs before anyone is let in:

- the token's deployment is the course's hub (``deployment_id``) and its *context* is the
  course (``course``: the LMS course's context id), so a token the same LMS issued for
  another course is refused;
- the hub user name is the one the roster gives: the value of the claim ``username_claim``
  (e.g. ``email`` or ``sub``) matched against the columns ``username``, ``lms_id``,
  ``sis_id`` and ``email`` of ``course/roster.csv``, else the value itself when it is a
  valid user name; the class file decides who may log in, as with passwords. The claim
  must be one students cannot edit (a managed e-mail, ``sub``, an LMS login id; never a
  display name): whoever it names is let in as that student;
- the instructor's account needs the LMS's Instructor role in the token.

The settings file (TOML, :func:`read_settings`) holds what the LMS administrator gives when
the tool is registered, no secret (the LMS signs with its private key; the hub needs only
its public keys).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from urllib.parse import urlsplit

from . import HubError, HubLayout, check_name

__all__ = ["LTISettings", "read_settings", "hub_name", "check_launch", "authenticator_class",
           "configure", "CONTEXT", "DEPLOYMENT", "ROLES", "INSTRUCTOR_ROLES", "REFUSED"]

CONTEXT = "https://purl.imsglobal.org/spec/lti/claim/context"
DEPLOYMENT = "https://purl.imsglobal.org/spec/lti/claim/deployment_id"
ROLES = "https://purl.imsglobal.org/spec/lti/claim/roles"
INSTRUCTOR_ROLES = ("http://purl.imsglobal.org/vocab/lis/v2/membership#Instructor",
                    "http://purl.imsglobal.org/vocab/lis/v2/institution/person#Instructor")
#: What a refused login's page says (HTTP 403), by reason.
REFUSED = {
    "deployment": "this LMS link is for another deployment of the tool",
    "course": "this LMS link is for another course",
    "name": "the LMS did not name you in a way this class knows",
    "role": "the instructor's account needs the LMS's Instructor role",
}


@dataclass(frozen=True)
class LTISettings:
    """The LMS's side of the tool's registration (module docstring)."""
    issuer: str          # the LMS's issuer identifier (``iss`` of its tokens)
    client_id: str       # the tool's client id in the LMS
    deployment_id: str   # the deployment of the tool the course's links use
    authorize_url: str   # the LMS's OIDC authorisation end-point
    jwks_url: str        # the LMS's public keys (JSON Web Key Set)
    course: str          # the context id of the LMS course
    username_claim: str = "email"   # the token's claim that names the student


def read_settings(path) -> LTISettings:
    """The LTI settings file: a TOML table with the fields of :class:`LTISettings`. A missing
    or empty field, an unknown one, or an end-point that is not https (http only on
    127.0.0.1, for a stand-in platform) is refused with its name."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise HubError(f"cannot read the LTI settings {path}: {e}") from None
    known = {f.name for f in fields(LTISettings)}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise HubError(f"{path}: unknown LTI setting(s) {', '.join(unknown)} (known: "
                       f"{', '.join(sorted(known))})")
    missing = [k for k in sorted(known - {"username_claim"}) if not str(raw.get(k, "")).strip()]
    if missing:
        raise HubError(f"{path}: LTI setting(s) {', '.join(missing)} missing or empty (the "
                       "LMS administrator gives them when the tool is registered)")
    settings = LTISettings(**{k: str(v).strip() for k, v in raw.items()})
    for key in ("issuer", "authorize_url", "jwks_url"):
        url = getattr(settings, key)
        parts = urlsplit(url)
        if not (parts.scheme == "https" and parts.hostname and not parts.username) and not (
                parts.scheme == "http" and parts.hostname == "127.0.0.1" and not parts.username):
            raise HubError(f"{path}: {key} = {url!r} must be an https:// address (the "
                           "LMS's keys and tokens must not travel in the clear)")
    return settings


def _roster_names(layout: HubLayout) -> dict[str, str]:
    """Every identifier of ``course/roster.csv`` (user name, LMS id, SIS id, e-mail, the
    last lower-cased) to its hub user name."""
    from .gradebook import read_roster

    names: dict[str, str | None] = {}

    def put(value: str, username: str) -> None:
        # an identifier two students share names neither (None): no silent last-row-wins
        names[value] = username if names.get(value, username) == username else None

    for username, row in read_roster(layout.course / "roster.csv").items():
        for key in ("lms_id", "sis_id", "email"):
            value = (row.get(key) or "").strip()
            if value:
                put(value.lower() if key == "email" else value, username)
        put(username, username)
    return names


def hub_name(claims: dict, settings: LTISettings, layout: HubLayout) -> str | None:
    """The hub user name the token names (module docstring), or None."""
    key = settings.username_claim
    source = claims.get("https://purl.imsglobal.org/spec/lti/claim/custom", {}) \
        if key.startswith("custom_") else claims
    value = str(source.get(key.removeprefix("custom_"), "") or "").strip()
    if not value:
        return None
    roster = _roster_names(layout)
    key = value if value in roster else value.lower()
    if key in roster:
        return roster[key]                     # None for an identifier two rows share
    try:
        check_name(value)
    except HubError:
        return None
    return value


def check_launch(claims: dict, settings: LTISettings, layout: HubLayout,
                 instructor: str) -> tuple[str | None, str | None]:
    """``(hub user name, None)`` for a token of the course, or ``(None, reason)`` with a
    key of :data:`REFUSED`. The token's signature, issuer, audience, age and nonce were
    checked before (by ltiauthenticator)."""
    if str(claims.get(DEPLOYMENT, "")) != settings.deployment_id:
        return None, "deployment"
    if str((claims.get(CONTEXT) or {}).get("id", "")) != settings.course:
        return None, "course"
    name = hub_name(claims, settings, layout)
    if name is None:
        return None, "name"
    if name == instructor and not set(claims.get(ROLES) or ()) & set(INSTRUCTOR_ROLES):
        return None, "role"
    return name, None


def authenticator_class():
    """:class:`CourseLTIAuthenticator`, made on first use (ltiauthenticator and JupyterHub
    are the hub's packages, not the library's)."""
    from ltiauthenticator.lti13.auth import LTI13Authenticator
    from ltiauthenticator.lti13.handlers import LTI13CallbackHandler
    from tornado import web
    from traitlets import Unicode

    from ... import _settings

    class CourseLTIAuthenticator(LTI13Authenticator):
        """LTI 1.3 login for the course's class (:mod:`annslam_lib.course.hub.lti`)."""

        settings_file = Unicode(config=True, help="the LTI settings file (TOML)")

        async def authenticate(self, handler, data=None):
            # JupyterHub also calls authenticate() from its login form and from the token
            # API (POST /hub/api/users/NAME/tokens with an "auth" body), with data the caller
            # wrote: only the LTI callback, which verified the LMS's signed token, may log in.
            if not isinstance(handler, LTI13CallbackHandler) or not isinstance(data, dict) \
                    or not isinstance(data.get(CONTEXT), dict):
                raise web.HTTPError(403, "log in from the LMS: this hub takes no other login")
            settings = read_settings(self.settings_file)
            name, why = check_launch(data or {}, settings, HubLayout.from_env(),
                                     _settings.hub_instructor())
            if name is None:
                context = (data or {}).get(CONTEXT) or {}
                self.log.warning("LTI login refused: %s (course context %r, deployment %r)",
                                 REFUSED[why], context.get("id"), (data or {}).get(DEPLOYMENT))
                raise web.HTTPError(403, REFUSED[why])
            return {"name": name, "auth_state": None}

    return CourseLTIAuthenticator


def configure(c, settings_file) -> LTISettings:
    """JupyterHub's config ``c`` set for LTI 1.3 login with the settings of
    ``settings_file`` (:func:`read_settings`)."""
    settings = read_settings(settings_file)
    c.JupyterHub.authenticator_class = authenticator_class()
    a = c.CourseLTIAuthenticator
    a.settings_file = str(Path(settings_file).resolve())
    a.issuer = settings.issuer
    a.client_id = {settings.client_id}
    a.authorize_url = settings.authorize_url
    a.jwks_endpoint = settings.jwks_url
    a.username_key = settings.username_claim
    return settings
