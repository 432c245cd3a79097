"""A big class on Zero to JupyterHub: what can be checked without a cluster.

hub/z2jh/config.yaml against the chart keys it uses (a schema written from the chart's
reference, which must refuse a misspelt key), its Python snippets run against stand-ins of
KubeSpawner's objects, its environment equal to a local class hub's; the image's Dockerfile
and binder/ built from the students' pinned environment on Python 3.11, as repo2docker itself
reads binder/ (its --no-build Dockerfile); and the files an image holds."""
from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import jsonschema
import pytest
import yaml
from traitlets.config import Config

from annslam_lib.course import hub
from annslam_lib.course.hub import setup as hub_setup

ROOT = Path(__file__).resolve().parents[1]
Z2JH = ROOT / "hub" / "z2jh"
IMAGE = hub.HubLayout(Path("/srv/annslam"))          # the hub folder inside the image


@pytest.fixture(scope="module")
def values():
    return yaml.safe_load((Z2JH / "config.yaml").read_text())


def _schema():
    return json.loads((Z2JH / "values-subset.schema.json").read_text())


def test_the_config_has_the_charts_keys_and_types(values):
    jsonschema.Draft202012Validator.check_schema(_schema())
    jsonschema.validate(values, _schema())


@pytest.mark.parametrize("path, bad", [
    (["singleuser", "memory", "limt"], "1G"),                       # misspelt key
    (["singleuser", "storage", "type"], "nfs"),                     # not a storage type
    (["cull", "timeout"], "an hour"),                               # not an integer
    (["singleuser", "storage", "extraVolumeMounts", 0, "mountPath"], "srv/data"),
    (["hub", "extraConfig", "x"], ["not", "code"]),
])
def test_the_schema_refuses_a_wrong_value(values, path, bad):
    v = copy.deepcopy(values)
    node = v
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = bad
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(v, _schema())


def _run_extra_config(values) -> Config:
    c = Config()
    for name, code in values["hub"]["extraConfig"].items():
        exec(compile(code, f"<extraConfig {name}>", "exec"), {"c": c})
    return c


def _spawner(uid: int, admin: bool, values):
    env = dict(values["singleuser"]["extraEnv"])
    vols = list(values["singleuser"]["storage"]["extraVolumes"])
    mounts = list(values["singleuser"]["storage"]["extraVolumeMounts"])
    return SimpleNamespace(user=SimpleNamespace(id=uid, admin=admin), environment=env,
                           volumes=vols, volume_mounts=mounts)


def test_each_student_runs_as_a_uid_of_their_own_and_only_the_instructor_grades(values):
    import asyncio

    c = _run_extra_config(values)
    uids = {c.KubeSpawner.uid(_spawner(i, False, values)) for i in range(1, 101)}
    assert len(uids) == 100 and min(uids) > 65535            # no system or image uid (1000)
    shared = _spawner(1, False, values)
    before = (dict(shared.environment), list(shared.volumes), list(shared.volume_mounts))
    teacher = _spawner(2, True, values)
    teacher.environment, teacher.volumes, teacher.volume_mounts = (
        shared.environment, shared.volumes, shared.volume_mounts)  # as the chart shares them
    asyncio.run(c.KubeSpawner.pre_spawn_hook(teacher))
    asyncio.run(c.KubeSpawner.pre_spawn_hook(shared))
    assert (shared.environment, shared.volumes, shared.volume_mounts) == before
    assert teacher.environment["JUPYTER_CONFIG_DIR"] == str(IMAGE.role_config("instructor"))
    assert {"name": "annslam-course", "mountPath": str(IMAGE.course)} in teacher.volume_mounts
    assert shared.environment["JUPYTER_CONFIG_DIR"] == str(IMAGE.role_config("student"))


def test_the_servers_environment_and_folders_are_a_local_hubs(values):
    su = values["singleuser"]
    want = {k: v for k, v in hub.server_env(IMAGE, "student").items() if k != "PATH"}
    assert su["extraEnv"] == want
    mounts = {m["name"]: m for m in su["storage"]["extraVolumeMounts"]}
    assert mounts["annslam-data"]["mountPath"] == str(IMAGE.data)
    assert mounts["annslam-data"]["readOnly"] is True
    assert mounts["annslam-exchange"]["mountPath"] == str(IMAGE.exchange)
    assert su["cmd"] == ["python", "-m", "annslam_lib", "singleuser", "--release",
                         str(IMAGE.release), "--"]
    env = _dockerfile_env()
    assert {k: env[k] for k in want} == want
    assert env["JUPYTER_CONFIG_DIR"] == str(IMAGE.role_config("student"))


def _dockerfile() -> str:
    return (Z2JH / "Dockerfile").read_text()


def _dockerfile_env() -> dict[str, str]:
    text = re.sub(r"\\\n\s*", " ", _dockerfile())
    env = {}
    for line in text.splitlines():
        if line.startswith("ENV "):
            env.update(dict(pair.split("=", 1) for pair in line[4:].split()))
    return env


def test_the_image_is_built_from_the_students_environment_on_python_3_11(values):
    text = _dockerfile()
    bases = re.findall(r"^FROM (\S+)", text, re.M)
    assert bases and all(b.startswith("python:3.11-") for b in bases)
    assert re.search(r"RUN python scripts/install\.py --venv /opt/annslam-env "
                     r"--base environment-student\.txt --wheel", text)
    assert f"--image-files {IMAGE.root}" in text
    # the final stage copies only the environment and the image files: no checkout
    final = text.split("\nFROM ")[-1]
    assert "COPY . " not in final and "/src" not in final.replace("--from=build", "")
    cmd = json.loads(re.search(r"^CMD (\[.*\])$", text, re.M).group(1))
    assert cmd == values["singleuser"]["cmd"]
    assert values["singleuser"]["image"]["name"].endswith("/annslam-student")


def test_binder_gives_repo2docker_the_same_pinned_environment():
    assert (ROOT / "binder" / "runtime.txt").read_text().split() == ["python-3.11"]
    reqs = [line.strip() for line in (ROOT / "binder" / "requirements.txt").read_text()
            .splitlines() if line.strip() and not line.startswith("#")]
    assert reqs == ["--extra-index-url https://download.pytorch.org/whl/cpu",
                    "-r ../environment-student.txt"]
    post = (ROOT / "binder" / "postBuild").read_text()
    assert "pip install --no-deps --no-cache-dir ." in post and "-e ." not in post
    assert "hub --image-files" in post and "rm -rf notebooks tests" in post


def test_repo2docker_builds_python_3_11_with_binders_requirements_then_post_build():
    """repo2docker's own reading of binder/ (the Dockerfile it would build, offline)."""
    exe = Path(sys.executable).parent / "jupyter-repo2docker"
    out = subprocess.run([str(exe), "--no-build", "--debug", "--user-id", "1000",
                          "--user-name", "jovyan", str(ROOT)], capture_output=True,
                         text=True, timeout=120)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-3000:]
    assert "python=3.11" in text
    copy_all = text.index("COPY --chown=1000:1000 src/ ${REPO_DIR}/")
    install = text.index('pip install --no-cache-dir -r "binder/requirements.txt"')
    post = text.index("RUN ./binder/postBuild")
    assert copy_all < install < post        # ../environment-student.txt is there by then


def test_an_image_holds_the_student_versions_and_both_roles_configurations(tmp_path):
    layout = hub.HubLayout(tmp_path / "srv")
    hub_setup.image_files(layout)
    released = sorted(p.name for p in layout.release.glob("*.ipynb"))
    assert released == sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb"))
    for p in layout.release.glob("*.ipynb"):
        assert "BEGIN SOLUTION" not in p.read_text()
    student = (layout.role_config("student") / "nbgrader_config.py").read_text()
    assert f"c.Exchange.root = {str(layout.exchange)!r}" in student
    assert "CourseDirectory.root" not in student
    server = json.loads((layout.role_config("student") / "jupyter_server_config.json")
                        .read_text())["ServerApp"]["jpserver_extensions"]
    assert server["nbgrader.server_extensions.formgrader"] is False
    instructor = (layout.role_config("instructor") / "nbgrader_config.py").read_text()
    assert f"c.CourseDirectory.root = {str(layout.course)!r}" in instructor
    assert all(p.stat().st_mode & 0o004 for p in layout.root.rglob("*"))


def test_idle_servers_are_culled_after_the_same_hour_as_on_a_local_hub(values):
    from annslam_lib.course.hub.config import IDLE_EVERY, IDLE_TIMEOUT

    assert values["cull"]["enabled"] is True
    assert (values["cull"]["timeout"], values["cull"]["every"]) == (IDLE_TIMEOUT, IDLE_EVERY)
