"""Open annotated MCAPs in the real Lichtblick web app (Foxglove Studio's
open-source line) in headless Chromium, as a user would, and fail on any alert
or any topic the app cannot list. Run by scripts/check-viewers.sh when
LOOMING_LICHTBLICK_WEB names a Lichtblick web build (docs/viewers.md says how to
make one with the kit in ../shared/viewer-check/).

usage: python3 check_lichtblick.py KIT_DIR WEB_BUILD LOOMING_BIN SHOTS_DIR FILE.mcap...

For each FILE: its layout from `looming layout`, a site with that layout as the
default, the range server, then two shots with the kit's shoot.py: opened with
no seek (`-open`) and seeked to its first near miss (`-seek`, when it has one).
Each shot's Alerts tab must say "No alerts found", and its Topics tab must list
every channel that has messages (from `looming inspect --json`) with a rate
above 0 Hz. Screenshots and texts stay in SHOTS_DIR.
"""
import datetime
import json
import os
import socket
import subprocess
import sys
import time

kit, web, looming, shots = sys.argv[1:5]
files = sys.argv[5:]
os.makedirs(shots, exist_ok=True)


def run(*args, **kw):
    return subprocess.run(args, check=True, capture_output=True, text=True, **kw).stdout


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def iso(ns):
    t = datetime.datetime.fromtimestamp(ns // 1_000_000_000, tz=datetime.timezone.utc)
    return t.strftime("%Y-%m-%dT%H:%M:%S") + f".{ns % 1_000_000_000:09d}Z"


def listed_topics(text):
    """(topic, schema, rate Hz, count) rows of the Topics tab's text."""
    lines = [line.strip() for line in text.splitlines()]
    rows = []
    for i, line in enumerate(lines):
        if line.startswith("/") and i + 3 < len(lines) and lines[i + 2].endswith(" Hz"):
            rows.append((line, lines[i + 1], float(lines[i + 2].split()[0]), lines[i + 3]))
    return rows


def shooter(kit, shots, topics):
    """The kit's shoot.py; for a log with more topics than its 1000-pixel
    window shows in the Topics tab (about 25 rows: the list only draws the
    rows in view, e.g. a log with three LiDARs), a copy with a window tall
    enough to list them all."""
    shoot = os.path.join(kit, "shoot.py")
    if topics <= 25:
        return shoot
    height = 1000 + 60 * (topics - 25)
    text = open(shoot).read()
    tall = text.replace('"height": 1000', f'"height": {height}')
    if tall == text:
        return shoot
    path = os.path.join(shots, "shoot-tall.py")
    with open(path, "w") as f:
        f.write(tall)
    return path


def check_shot(prefix, expected):
    alerts = open(f"{prefix}-alerts.txt").read()
    problems = []
    if "No alerts found" not in alerts:
        body = alerts.split("Layouts", 1)[-1].strip()
        problems.append("alerts:\n      " + body.replace("\n", "\n      "))
    listed = {topic: rate for topic, _, rate, _ in listed_topics(open(f"{prefix}-topics.txt").read())}
    missing = sorted(t for t in expected if t not in listed)
    still = sorted(t for t in expected if t in listed and listed[t] <= 0)
    if missing:
        problems.append(f"{len(missing)} topics missing from the Topics tab: {', '.join(missing)}")
    if still:
        problems.append(f"{len(still)} topics at 0 Hz: {', '.join(still)}")
    return problems, len(listed)


failed = False
table = []
for path in files:
    name = os.path.splitext(os.path.basename(path))[0]
    inspect = json.loads(run(looming, "inspect", path, "--json"))
    expected = sorted({c["topic"] for c in inspect["channels"] if c.get("message_count", 0) > 0})
    layout = os.path.join(shots, f"{name}.layout.json")
    run(looming, "layout", path, "-o", layout, "--force")
    # Ranked by time to contact: the first is the worst near miss.
    events = json.loads(run(looming, "events", path, "--json"))
    site = os.path.join(shots, f"{name}.site")
    run(sys.executable, os.path.join(kit, "make_site.py"), web, site, layout, path)
    port = free_port()
    server = subprocess.Popen([sys.executable, os.path.join(kit, "rangeserver.py"), str(port), site],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(1)
        runs = [("open", "-")]
        if events:
            runs.append(("seek", iso(events[0]["start_log_time_ns"])))
        for label, at in runs:
            prefix = os.path.join(shots, f"{name}-{label}")
            run(sys.executable, shooter(kit, shots, len(expected)), str(port), os.path.basename(path), at, "25", prefix)
            problems, listed = check_shot(prefix, expected)
            table.append((name, label, "none" if not problems else "PROBLEMS", listed, len(expected)))
            for problem in problems:
                print(f"check-lichtblick: FAIL: {path} ({label}): {problem}", file=sys.stderr)
                failed = True
    finally:
        server.terminate()
        server.wait()

print(f"\n{'file':<36} {'shot':<5} {'alerts':<9} {'topics listed / with messages'}")
for name, label, alerts, listed, expected in table:
    print(f"{name:<36} {label:<5} {alerts:<9} {listed} / {expected}")
print(f"screenshots: {shots}")
sys.exit(1 if failed else 0)
