"""Download, verification and CLI of the data layer, against a real local HTTP server.

Each test uses its own data dir (tmp_path) and a registry with two tiny datasets,
so the user's cache and the real registry are never touched."""
import functools
import hashlib
import http.server
import os
import re
import socket
import threading
from pathlib import Path

import platformdirs
import pytest


from annslam_lib.course.cli import main
from annslam_lib.data.fetch import DataError
from annslam_lib.data.registry import DataFile, DatasetEntry
from annslam_lib.data import fetch
from annslam_lib.data import registry

GOOD = b"annslam test payload\n" * 500
SHA = hashlib.sha256(GOOD).hexdigest()
FIX = re.escape(fetch.fetch_command("").rstrip())


class _Handler(http.server.SimpleHTTPRequestHandler):
    requests: list[str] = []

    def do_GET(self):
        self.requests.append(self.path)
        super().do_GET()

    def log_message(self, *args):  # keep the test output clean
        pass


@pytest.fixture
def server(tmp_path):
    """A static file server on 127.0.0.1 (free port) serving ``www/``:
    ``tiny/good.bin`` (correct bytes) and ``broken/bad.bin`` (one byte flipped)."""
    www = tmp_path / "www"
    for folder, name, data in (("tiny", "good.bin", GOOD), ("broken", "bad.bin", b"X" + GOOD[1:])):
        (www / folder).mkdir(parents=True)
        (www / folder / name).write_bytes(data)
    _Handler.requests = []
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Handler, directory=www))
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()
    thread.join(timeout=5)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def data(tmp_path, monkeypatch, server):
    """Data dir ``tmp_path/data``, mirror = the local server, registry = two tiny datasets."""
    entry = functools.partial(DatasetEntry, citation="test", licence="test", source="test")
    url = f"http://127.0.0.1:{_closed_port()}/unused"  # registry URLs must not be used here
    monkeypatch.setattr(registry, "DATASETS", {
        "tiny": entry(name="tiny", folder="tiny", files=(DataFile("good.bin", SHA, len(GOOD), url),)),
        "broken": entry(name="broken", folder="broken", files=(DataFile("bad.bin", SHA, len(GOOD), url),)),
    })
    monkeypatch.setenv("ANNSLAM_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("ANNSLAM_DATA_URL", server)
    return tmp_path / "data"


def test_data_dir_resolution(monkeypatch, tmp_path):
    monkeypatch.delenv("ANNSLAM_DATA", raising=False)
    assert fetch.data_dir() == Path(platformdirs.user_cache_dir("annslam")) / "data"
    monkeypatch.setenv("ANNSLAM_DATA", str(tmp_path))
    assert fetch.data_dir() == tmp_path
    assert fetch.dataset_dir("victoria_park") == tmp_path / "acfr_victoria_park"


def test_urls(monkeypatch):
    monkeypatch.delenv("ANNSLAM_DATA_URL", raising=False)
    assert fetch.url("car_park", "data_set.mat") == (
        "https://raw.githubusercontent.com/yuzehai1995/hwork_SLAM/"
        "b4715234d795a5dd8155371e99b71f99803eb551/hw4_slam/data_set.mat")
    monkeypatch.setenv("ANNSLAM_DATA_URL", "file:///mirror/")
    assert fetch.url("car_park", "data_set.mat") == "file:///mirror/acfr_car_park/data_set.mat"
    pattern = re.compile(r"https://raw\.githubusercontent\.com/[\w.-]+/[\w.-]+/[0-9a-f]{40}/(.+/)?(.+)")
    for entry in registry.DATASETS.values():
        for f in entry.files:
            m = pattern.fullmatch(f.url)
            assert m and m.group(2) == f.name and re.fullmatch(r"[0-9a-f]{64}", f.sha256)


def test_registry_matches_the_shipped_sha256sums():
    root = os.environ.get("ANNSLAM_DATA")
    if not root:
        pytest.skip("ANNSLAM_DATA is not set: no reference SHA256SUMS to compare with")
    for entry in registry.DATASETS.values():
        sums = dict(line.split()[::-1] for line in (Path(root) / entry.folder / "SHA256SUMS").open())
        for f in entry.files:
            assert sums[f.name] == f.sha256
            assert (Path(root) / entry.folder / f.name).stat().st_size == f.size


def test_download_verifies_and_leaves_no_temp_files(data):
    p = fetch.path("tiny", "good.bin", progress=False)
    assert p == data / "tiny" / "good.bin" and p.read_bytes() == GOOD
    assert os.listdir(data / "tiny") == ["good.bin"]
    assert _Handler.requests == ["/tiny/good.bin"]
    assert fetch.ensure("tiny") == data / "tiny"  # present and verified: no second request
    assert _Handler.requests == ["/tiny/good.bin"]


def test_corrupt_download_raises_and_saves_nothing(data):
    with pytest.raises(DataError) as err:
        fetch.ensure("broken", progress=False)
    msg = str(err.value)
    assert SHA in msg and hashlib.sha256(b"X" + GOOD[1:]).hexdigest() in msg
    assert re.search(f"{FIX} broken", msg) and "ANNSLAM_DATA" in msg and "bad.bin" in msg
    assert os.listdir(data / "broken") == []


@pytest.mark.parametrize("where", ["mirror", "registry"])
def test_unreachable_server_is_a_data_error(data, monkeypatch, where):
    dead = f"http://127.0.0.1:{_closed_port()}"
    if where == "mirror":
        monkeypatch.setenv("ANNSLAM_DATA_URL", dead)
    else:  # no mirror: the registry URL is used
        monkeypatch.delenv("ANNSLAM_DATA_URL")
        f = DataFile("good.bin", SHA, len(GOOD), f"{dead}/good.bin")
        monkeypatch.setitem(registry.DATASETS, "tiny", DatasetEntry("tiny", "tiny", (f,), "", "", ""))
    with pytest.raises(DataError, match=rf"(?s)cannot download .*{dead}.*{SHA}.*{FIX} tiny"):
        fetch.path("tiny", "good.bin", progress=False)
    assert not (data / "tiny" / "good.bin").exists()
    assert not any((data / "tiny").iterdir())


def test_missing_on_server_is_a_data_error(data, monkeypatch):
    monkeypatch.setenv("ANNSLAM_DATA_URL", os.environ["ANNSLAM_DATA_URL"] + "/nowhere")
    with pytest.raises(DataError, match="404"):
        fetch.ensure("tiny", progress=False)


def test_existing_corrupt_file_raises_until_repaired(data):
    (data / "tiny").mkdir(parents=True)
    (data / "tiny" / "good.bin").write_bytes(GOOD[:-1])
    with pytest.raises(DataError, match=rf"(?s)'good.bin'.*corrupt.*expected sha256: {SHA}.*{FIX} tiny"):
        fetch.path("tiny", "good.bin")
    assert _Handler.requests == []  # not silently replaced
    fetch.ensure("tiny", repair=True, progress=False)
    assert (data / "tiny" / "good.bin").read_bytes() == GOOD


def test_a_changed_file_is_hashed_again(data):
    p = fetch.path("tiny", "good.bin", progress=False)
    p.write_bytes(b"Y" + GOOD[1:])  # same size; a new mtime invalidates the cached verification
    os.utime(p, ns=(0, 0))
    with pytest.raises(DataError, match="corrupt"):
        fetch.verify("tiny")


def test_read_only_data_dir_with_a_missing_file(data):
    (data / "tiny").mkdir(parents=True)
    (data / "tiny").chmod(0o555)
    try:
        with pytest.raises(DataError, match=rf"(?s)read-only.*{SHA}"):
            fetch.ensure("tiny", progress=False)
    finally:
        (data / "tiny").chmod(0o755)
    assert _Handler.requests == [] and not any((data / "tiny").iterdir())


def test_cli(data, capsys):
    assert main(["data", "verify", "tiny"]) == 1
    assert re.search(f"{FIX} tiny", capsys.readouterr().err)
    assert main(["data", "fetch", "tiny"]) == 0
    assert main(["data", "verify", "tiny"]) == 0
    (data / "tiny" / "good.bin").write_bytes(b"corrupt")
    assert main(["data", "verify"]) == 1  # all datasets: tiny corrupt, broken missing
    err = capsys.readouterr().err
    assert "tiny: FAILED" in err and "broken: FAILED" in err and SHA in err
    assert main(["data", "fetch", "tiny"]) == 0 and main(["data", "verify", "tiny"]) == 0
    assert main(["data", "fetch"]) == 1  # broken cannot be fetched
    assert main(["data", "verify", "nope"]) == 2
    assert "known datasets: tiny, broken" in capsys.readouterr().err
    assert main(["data", "where"]) == 0 and capsys.readouterr().out.strip() == str(data)
    assert main(["data", "list", "tiny"]) == 0 and "cite:    test" in capsys.readouterr().out


def test_unknown_dataset_lists_the_known_names():
    with pytest.raises(ValueError, match="unknown dataset 'nope'; known datasets: car_park, victoria_park, mrclam7"):
        fetch.ensure("nope")
    with pytest.raises(ValueError, match="has no file 'x.mat'; its files are: data_set.mat, beac_juan3.mat"):
        fetch.path("car_park", "x.mat")


def test_the_fix_command_in_a_missing_data_error_works_as_printed(car_park, tmp_path):
    """The command a DataError prints is pasted into a shell as it stands and fetches the
    data (from a file:// mirror of the real files, laid out like the data folder)."""
    import subprocess

    env = dict(os.environ, ANNSLAM_DATA=str(tmp_path / "data"),
               ANNSLAM_DATA_URL=fetch.data_dir().as_uri())
    old = {k: os.environ.get(k) for k in ("ANNSLAM_DATA", "ANNSLAM_DATA_URL")}
    os.environ.update(ANNSLAM_DATA=env["ANNSLAM_DATA"])
    try:
        with pytest.raises(DataError) as err:
            fetch.verify("car_park")
    finally:
        for k, v in old.items():
            os.environ.pop(k, None) if v is None else os.environ.__setitem__(k, v)
    command = re.search(r"Fix: run  (.+?)  \(", str(err.value)).group(1)
    out = subprocess.run(command, shell=True, env=env, capture_output=True, text=True,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "car_park: OK" in out.stdout
    assert (tmp_path / "data" / "acfr_car_park" / "data_set.mat").exists()


# ------------------------------------------------------------- hostile or slow mirrors

class _Hostile(http.server.BaseHTTPRequestHandler):
    """tiny/: a byte every 0.2 s, for 40 s; broken/: 300x the expected size in zeros."""

    def do_GET(self):
        import time

        self.send_response(200)
        self.end_headers()
        try:
            if "/tiny/" in self.path:
                for _ in range(200):
                    self.wfile.write(b"a")
                    self.wfile.flush()
                    time.sleep(0.2)
            else:
                block = b"\0" * (1 << 16)
                for _ in range(300 * len(GOOD) // len(block) + 1):
                    self.wfile.write(block)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def log_message(self, *args):
        pass


@pytest.fixture
def hostile(data, monkeypatch):
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Hostile)
    httpd.daemon_threads = True
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    monkeypatch.setenv("ANNSLAM_DATA_URL", f"http://127.0.0.1:{httpd.server_address[1]}")
    yield data
    httpd.shutdown()
    httpd.server_close()


def test_a_trickling_mirror_hits_the_files_deadline(hostile, monkeypatch):
    import time

    monkeypatch.setattr(fetch, "DEADLINE_BASE_S", 1.0)      # 1 s + 10 kB at 50 kB/s = 1.2 s
    t0 = time.monotonic()
    with pytest.raises(DataError, match=r"deadline for this file") as err:
        fetch.ensure("tiny", progress=False)
    took = time.monotonic() - t0
    assert 1.2 <= took < 4.0, took
    assert "ANNSLAM_DATA_URL" in str(err.value)
    assert list((hostile / "tiny").iterdir()) == []        # the partial file is gone


def test_a_flooding_mirror_is_cut_off_at_the_files_size(hostile):
    with pytest.raises(DataError, match=r"more than the file's 10500 bytes \(cut off at (\d+)\)") as err:
        fetch.ensure("broken", progress=False)
    cut = int(re.search(r"cut off at (\d+)", str(err.value)).group(1))
    assert cut <= len(GOOD) + fetch.SIZE_SLACK + (1 << 16)   # one read past the limit, not 3 MB
    assert list((hostile / "broken").iterdir()) == []


def test_a_killed_downloads_partial_file_is_removed_by_the_next(data, monkeypatch):
    import time

    folder = data / "tiny"
    folder.mkdir(parents=True)
    orphan, fresh = folder / ".good.bin.k3j2.part", folder / ".good.bin.live.part"
    orphan.write_bytes(b"half")
    fresh.write_bytes(b"another download, still running")
    old = time.time() - fetch.STALE_PART_S - 5
    os.utime(orphan, (old, old))
    fetch.ensure("tiny", progress=False)
    assert sorted(p.name for p in folder.iterdir()) == [".good.bin.live.part", "good.bin"]


def test_verify_rehashes_a_flipped_byte_that_kept_size_and_mtime(data):
    fetch.ensure("tiny", progress=False)
    p = data / "tiny" / "good.bin"
    st = p.stat()
    fetch.path("tiny", "good.bin")                           # cached as verified
    raw = bytearray(p.read_bytes())
    raw[100] ^= 0x01
    p.write_bytes(bytes(raw))
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))        # size and mtime as before
    assert (p.stat().st_size, p.stat().st_mtime_ns) == (st.st_size, st.st_mtime_ns)
    with pytest.raises(DataError, match="corrupt"):
        fetch.verify("tiny")
    with pytest.raises(DataError, match="corrupt"):
        fetch.path("tiny", "good.bin")                      # the load path sees it too (ctime)


def test_an_empty_annslam_data_is_an_error(monkeypatch):
    monkeypatch.setenv("ANNSLAM_DATA", "")
    with pytest.raises(DataError, match=r"set but empty.*Unset it"):
        fetch.data_dir()
    monkeypatch.setenv("ANNSLAM_DATA", "   ")
    with pytest.raises(DataError, match="set but empty"):
        fetch.data_dir()
