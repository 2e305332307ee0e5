#!/usr/bin/env bash
# Check that annotated MCAPs open in third-party readers: the Python `mcap`
# library, Rerun's MCAP importer and, when LOOMING_LICHTBLICK_WEB names a
# Lichtblick web build, the real Lichtblick app (Foxglove Studio's open-source
# line) in headless Chromium. Outside CI: the first run creates a Python venv
# and downloads ~250 MB from PyPI (rerun-sdk, pyarrow, numpy), ~30 s and
# ~820 MB on disk; later runs reuse it and take a few seconds per file (the
# Lichtblick check about 35 s per file).
#
# Usage: scripts/check-viewers.sh [ANNOTATED.mcap...]
#   default: out/cut-in-annotated.mcap and its near-miss clip (out/clips/), and,
#   when ../shared/real-data/ is there, out/kitti-22-annotated.mcap (KITTI, a
#   pass-through output) and its first clip. Missing defaults (or all of them with
#   LOOMING_VIEWER_REBUILD=1) are made first with `cargo run --release -- process
#   ... --clips out/clips 2`.
#
# Environment:
#   LOOMING_VIEWER_VENV    venv directory (default target/viewer-venv; reused if present)
#   LOOMING_VIEWER_PYTHON  interpreter that creates the venv (default python3, >= 3.10)
#   LOOMING_VIEWER_RRD     also keep the Rerun recording of the last file at this path
#                          (open it with `$LOOMING_VIEWER_VENV/bin/rerun FILE.rrd`)
#   LOOMING_VIEWER_REBUILD=1  regenerate the default outputs before checking
#   LOOMING_LICHTBLICK_WEB a Lichtblick web build (`lb/web/.webpack`, docs/viewers.md);
#                          unset: the Lichtblick check is skipped, and said so
#   LOOMING_VIEWER_KIT     the viewer kit (default ../shared/viewer-check)
#   LOOMING_LICHTBLICK_SHOTS  where its screenshots stay (default target/lichtblick-shots)
#   (relative LOOMING_VIEWER_* paths are taken from the repository root, the MCAP
#   arguments from the current directory)
#
# What it checks (exit status 1 with a FAIL line on the first problem):
#   1. mcap (Python): the whole file is read record by record with CRC
#      validation on (chunk CRCs, data-section CRC, plus the summary CRC checked
#      here), then again through the summary index; per-topic message counts must
#      agree with each other and with the Statistics record. These /looming/*
#      channels must exist with >= 1 message: points, disagreement, threat,
#      threat_zones, image/fused, image/disagreement; /looming/events and
#      /looming/log must exist (0 messages allowed).
#      Every /looming/points message is decoded with protobuf from the schema the
#      channel declares (encoding `protobuf`, FileDescriptorSet, `foxglove.PointCloud`):
#      fields x,y,z (FLOAT32) and red,green,blue,alpha (UINT8), point_stride * N == len(data).
#      Every /looming/image/* message is decoded as `foxglove.CompressedImage` with
#      format `png`, and its PNG with Pillow: RGB, the same size in every message.
#   2. Rerun: `rerun mcap convert` turns the MCAP into an .rrd (the importer the
#      viewer uses when it opens an .mcap), `rerun rrd verify` must pass, and the
#      recording is read back with `rerun.chunk.RrdReader`: entity /looming/points
#      must carry Points3D:positions and Points3D:colors, one row per MCAP message,
#      the same number of points per message, and, for the first message, the same
#      coordinates and RGBA values as decoded from the MCAP. Entities
#      /looming/image/* must carry EncodedImage:blob with media type image/png, one
#      row per MCAP message, the first blob byte-identical to the MCAP's PNG (the
#      viewer decodes it with the `image` crate, as tests/annotate.rs does).
#   It ends with a table: topic, messages, and what Rerun made of the topic.
#   3. Lichtblick (scripts/check_lichtblick.py): each file opened as a user opens
#      it (no seek) and seeked to its first near miss, with the layout of `looming
#      layout`; its Alerts tab must be empty and its Topics tab must list every
#      channel with messages at a rate above 0 Hz.
set -euo pipefail
caller=$PWD
cd "$(dirname "$0")/.."
root=$PWD

die() { echo "check-viewers: FAIL: $*" >&2; exit 1; }

default_mcap=out/cut-in-annotated.mcap
kitti_input=$root/../shared/real-data/kitti-22-scans-lidar-only.mcap
kitti_mcap=out/kitti-22-annotated.mcap
mcaps=()
for arg in "$@"; do
  [[ $arg == /* ]] && mcaps+=("$arg") || mcaps+=("$caller/$arg")
done
venv=${LOOMING_VIEWER_VENV:-target/viewer-venv}
python=${LOOMING_VIEWER_PYTHON:-python3}

# Exact versions verified together (Python 3.11, Linux x86_64). rerun-sdk >= 0.30
# is needed for foxglove.PointCloud -> Points3D; the checks read the .rrd through
# the `rerun.chunk` API of 0.41, so keep this pin unless the script is updated.
requirements=(
  mcap==1.6.0
  protobuf==7.36.2
  rerun-sdk==0.41.0
  # dependencies of the above, pinned too so the venv is reproducible
  zstandard==0.25.0 lz4==4.4.5
  numpy==2.4.6 pyarrow==26.0.1 attrs==26.1.0 pillow==13.0.0 psutil==7.2.2 typing-extensions==4.16.0
)

# 1. Python venv ---------------------------------------------------------------
if [[ ! -x $venv/bin/python ]]; then
  "$python" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
    || die "$python: not found or older than 3.10 (rerun-sdk 0.41 needs >= 3.10); set LOOMING_VIEWER_PYTHON"
  echo "check-viewers: creating $venv with $("$python" --version 2>&1)" >&2
  "$python" -m venv "$venv"
fi
stamp=$venv/.check-viewers-requirements
wanted=$(printf '%s\n' "${requirements[@]}" | sed '/^$/d')
if [[ ! -f $stamp || $(cat "$stamp") != "$wanted" ]]; then
  echo "check-viewers: installing into $venv: $(echo $wanted)" >&2
  start=$SECONDS
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check $wanted \
    || die "pip install into $venv failed"
  echo "$wanted" > "$stamp"
  echo "check-viewers: installed in $((SECONDS - start)) s" >&2
fi

# 2. The annotated MCAPs -------------------------------------------------------
make_default() {  # INPUT OUTPUT
  if [[ ! -f $2 || ${LOOMING_VIEWER_REBUILD:-0} == 1 ]]; then
    echo "check-viewers: making $2 and its clips" >&2
    cargo run --release -q -- process "$1" -o "$2" --force --clips out/clips 2 -q
  fi
}
if [[ ${#mcaps[@]} == 0 ]]; then
  make_default sample_logs/cut-in.mcap "$default_mcap"
  mcaps+=("$root/$default_mcap" "$root/out/clips/cut-in-annotated.event-1.mcap")
  if [[ -f $kitti_input ]]; then
    make_default "$kitti_input" "$kitti_mcap"
    mcaps+=("$root/$kitti_mcap" "$root/out/clips/kitti-22-annotated.event-1.mcap")
  fi
fi
for mcap in "${mcaps[@]}"; do [[ -f $mcap ]] || die "$mcap: no such file"; done

# 3. The checks -----------------------------------------------------------------
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
rrd=${LOOMING_VIEWER_RRD:-$work/recording.rrd}

cat > "$work/check.py" <<'PY'
import collections, importlib.metadata, io, os, subprocess, sys, zlib

import numpy as np
import pyarrow as pa
import pyarrow.compute  # pa.compute.sum
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema, Statistics
from mcap.stream_reader import StreamReader, breakup_chunk
from PIL import Image

MCAP, RRD, HINT = sys.argv[1], sys.argv[2], sys.argv[3]
POINTS = "/looming/points"
NEED_MESSAGES = [POINTS, "/looming/disagreement", "/looming/threat", "/looming/threat_zones",
                 "/looming/image/fused", "/looming/image/disagreement"]
NEED_CHANNEL = ["/looming/events", "/looming/log"]
IMAGES = ["/looming/image/fused", "/looming/image/disagreement"]
FLOAT32, UINT8 = 7, 1  # foxglove.PackedElementField.NumericType


def fail(msg):
    print(f"check-viewers: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def say(msg):
    print(f"check-viewers: {msg}", flush=True)


# ---- 1. mcap: linear read with CRC validation ----------------------------------
def message_class(schema):
    """Build the protobuf class of `schema` from the FileDescriptorSet it carries."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    pending = {fd.name: fd for fd in fds.file}

    def add(name):
        fd = pending.pop(name, None)
        if fd is not None:
            for dep in fd.dependency:
                add(dep)
            pool.Add(fd)

    for name in list(pending):
        add(name)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


schemas, channels, classes = {}, {}, {}
counts = collections.Counter()          # channel id -> messages
points_per_message = []                 # (log_time, n) for every /looming/points message
first_cloud = None                      # (log_time, xyz float32 [N,3], rgba uint32 [N])
first_png = {}                          # image topic -> (log_time, PNG bytes)
image_sizes = collections.defaultdict(set)  # image topic -> {(width, height)}
crc_chunks = 0
data_crc = summary_crc_checked = False
footer = stats = None


def check_cloud(msg, log_time):
    global first_cloud
    ch = channels[msg.channel_id]
    schema = schemas.get(ch.schema_id)
    if (schema is None or schema.encoding != "protobuf" or schema.name != "foxglove.PointCloud"
            or ch.message_encoding != "protobuf"):
        fail(f"{POINTS}: expected protobuf foxglove.PointCloud, channel declares message encoding "
             f"{ch.message_encoding!r}, schema {getattr(schema, 'name', None)!r} "
             f"({getattr(schema, 'encoding', None)!r})")
    if schema.id not in classes:
        try:
            classes[schema.id] = message_class(schema)
        except Exception as e:
            fail(f"{POINTS}: cannot build foxglove.PointCloud from the channel's FileDescriptorSet: {e}")
    cloud = classes[schema.id].FromString(msg.data)
    fields = {f.name: f for f in cloud.fields}
    need = {"x": FLOAT32, "y": FLOAT32, "z": FLOAT32, "red": UINT8, "green": UINT8, "blue": UINT8, "alpha": UINT8}
    for name, ty in need.items():
        if name not in fields:
            fail(f"{POINTS} @ {log_time}: no field {name!r} (fields: {sorted(fields)})")
        if fields[name].type != ty:
            fail(f"{POINTS} @ {log_time}: field {name!r} has type {fields[name].type}, expected {ty}")
        size = 4 if ty == FLOAT32 else 1
        if fields[name].offset + size > cloud.point_stride:
            fail(f"{POINTS} @ {log_time}: field {name!r} (offset {fields[name].offset}) "
                 f"past point_stride {cloud.point_stride}")
    n = len(cloud.data) // cloud.point_stride
    if cloud.point_stride * n != len(cloud.data):
        fail(f"{POINTS} @ {log_time}: point_stride {cloud.point_stride} * {n} != len(data) {len(cloud.data)}")
    points_per_message.append((log_time, n))
    if first_cloud is None:
        raw = np.frombuffer(cloud.data, dtype=np.uint8).reshape(n, cloud.point_stride)
        col = lambda f, w: raw[:, fields[f].offset:fields[f].offset + w]
        xyz = np.stack([col(a, 4).copy().view("<f4")[:, 0] for a in "xyz"], axis=1)
        r, g, b, a = (col(c, 1)[:, 0].astype(np.uint32) for c in ("red", "green", "blue", "alpha"))
        first_cloud = (log_time, xyz, (r << 24) | (g << 16) | (b << 8) | a, cloud.frame_id, cloud.point_stride)


def check_image(msg, log_time):
    ch = channels[msg.channel_id]
    schema = schemas.get(ch.schema_id)
    if (schema is None or schema.encoding != "protobuf" or schema.name != "foxglove.CompressedImage"
            or ch.message_encoding != "protobuf"):
        fail(f"{ch.topic}: expected protobuf foxglove.CompressedImage, channel declares message encoding "
             f"{ch.message_encoding!r}, schema {getattr(schema, 'name', None)!r}")
    if schema.id not in classes:
        classes[schema.id] = message_class(schema)
    image = classes[schema.id].FromString(msg.data)
    if image.format != "png":
        fail(f"{ch.topic} @ {log_time}: format {image.format!r}, expected 'png'")
    try:
        decoded = Image.open(io.BytesIO(image.data))
        decoded = decoded.convert("RGB")
    except Exception as e:
        fail(f"{ch.topic} @ {log_time}: the PNG does not decode: {type(e).__name__}: {e}")
    image_sizes[ch.topic].add(decoded.size)
    first_png.setdefault(ch.topic, (log_time, bytes(image.data)))


def handle(rec):
    global footer, stats, data_crc
    if isinstance(rec, Schema):
        if rec.id in schemas and (schemas[rec.id].name, schemas[rec.id].data) != (rec.name, rec.data):
            fail(f"schema id {rec.id} defined twice with different contents")
        schemas[rec.id] = rec
    elif isinstance(rec, Channel):
        if rec.id in channels and channels[rec.id].topic != rec.topic:
            fail(f"channel id {rec.id} defined twice ({channels[rec.id].topic}, {rec.topic})")
        channels[rec.id] = rec
    elif isinstance(rec, Message):
        if rec.channel_id not in channels:
            fail(f"message on channel id {rec.channel_id} before its Channel record")
        counts[rec.channel_id] += 1
        if channels[rec.channel_id].topic == POINTS:
            check_cloud(rec, rec.log_time)
        elif channels[rec.channel_id].topic in IMAGES:
            check_image(rec, rec.log_time)
    elif isinstance(rec, Statistics):
        stats = rec
    elif isinstance(rec, DataEnd):
        data_crc = rec.data_section_crc != 0   # StreamReader compared it already
    elif isinstance(rec, Footer):
        footer = rec


try:
    with open(MCAP, "rb") as f:
        for rec in StreamReader(f, validate_crcs=True, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                crc_chunks += rec.uncompressed_crc != 0
                for inner in breakup_chunk(rec, validate_crc=True):
                    handle(inner)
            else:
                handle(rec)
except Exception as e:  # McapError, CRCValidationError (not an McapError), zstd/lz4 errors, EOF...
    fail(f"{MCAP}: mcap read (validate_crcs=True) failed: {type(e).__name__}: {e}")

# The Python reader does not check the Footer's summary CRC: do it here. It covers
# the summary section up to and including the footer's summary_offset_start field.
size = os.path.getsize(MCAP)
if footer is not None and footer.summary_crc != 0:
    start = footer.summary_start or size - 8 - 29
    with open(MCAP, "rb") as f:
        f.seek(start)
        crc = zlib.crc32(f.read(size - 12 - start))
    if crc != footer.summary_crc:
        fail(f"{MCAP}: summary CRC mismatch (footer {footer.summary_crc:#010x}, computed {crc:#010x})")
    summary_crc_checked = True

by_topic = collections.Counter()
for cid, ch in channels.items():
    by_topic[ch.topic] += counts[cid]
say(f"mcap {MCAP}: {sum(counts.values())} messages on {len(channels)} channels; CRCs validated: "
    f"{crc_chunks} chunk(s), data section {'yes' if data_crc else 'absent'}, "
    f"summary {'yes' if summary_crc_checked else 'absent'}")

# Indexed read (what viewers do): the summary + chunk indexes must give the same counts.
try:
    with open(MCAP, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            fail(f"{MCAP}: no summary section (viewers need it to seek)")
        indexed = collections.Counter(ch.topic for _, ch, _ in reader.iter_messages(log_time_order=False))
except Exception as e:
    fail(f"{MCAP}: indexed read failed: {type(e).__name__}: {e}")
if indexed != +by_topic:
    fail(f"{MCAP}: indexed read counts {dict(indexed)} != linear read counts {dict(+by_topic)}")
missing_in_summary = {ch.topic for ch in channels.values()} - {ch.topic for ch in summary.channels.values()}
if missing_in_summary:
    fail(f"{MCAP}: channels missing from the summary: {sorted(missing_in_summary)}")
if stats is not None:
    for cid, n in stats.channel_message_counts.items():
        if counts[cid] != n:
            fail(f"{MCAP}: Statistics says {n} messages on channel {cid} "
                 f"({channels[cid].topic if cid in channels else '?'}), file has {counts[cid]}")

for topic in NEED_MESSAGES + NEED_CHANNEL:
    if topic not in by_topic:
        fail(f"{MCAP}: channel {topic} is missing{HINT}")
for topic in NEED_MESSAGES:
    if by_topic[topic] == 0:
        fail(f"{MCAP}: channel {topic} has no messages{HINT}")
t0, xyz0, rgba0, frame0, stride0 = first_cloud
mcap_n = collections.defaultdict(list)      # log_time -> point counts of the messages at that time
for t, n in points_per_message:
    mcap_n[t].append(n)
for topic in IMAGES:
    if len(image_sizes[topic]) != 1:
        fail(f"{topic}: image sizes {sorted(image_sizes[topic])}, expected one size for the whole log")
    (width, height), = image_sizes[topic]
    say(f"mcap {topic}: {by_topic[topic]} messages decoded as foxglove.CompressedImage, "
        f"PNGs of {width} x {height} (Pillow)")
say(f"mcap {POINTS}: {len(points_per_message)} messages decoded as foxglove.PointCloud, "
    f"{sum(n for _, n in points_per_message)} points; first: {len(xyz0)} points, stride {stride0}, "
    f"frame_id {frame0!r}")

# ---- 2. Rerun: MCAP -> RRD with the importer, verify, read back ----------------
rerun_cli = os.path.join(os.path.dirname(sys.executable), "rerun")  # the CLI bundled in rerun-sdk
import rerun as rr
from rerun.chunk import RrdReader

def run(args, what):
    p = subprocess.run([rerun_cli, *args], capture_output=True, text=True)
    if p.returncode != 0:
        fail(f"{what} failed (exit {p.returncode}):\n{p.stdout}{p.stderr}")
    return p

run(["mcap", "convert", MCAP, "-o", RRD, "--application-id", "looming_check_viewers"],
    "rerun mcap convert")
run(["rrd", "verify", RRD], "rerun rrd verify (one known cause: a foxglove.PointCloud whose pose, "
    "pose.position or pose.orientation is unset gives null InstancePoses3D columns)")
say(f"rerun {rr.__version__}: `rerun mcap convert` -> {RRD}, `rerun rrd verify` ok")

entities = {}                                # entity path -> what Rerun made of it
positions = collections.defaultdict(list)    # /looming/points: log_time -> [positions row]
colors = collections.defaultdict(list)       # /looming/points: log_time -> [colours row]
points_schema = None
for chunk in RrdReader(RRD).stream():
    e = entities.setdefault(chunk.entity_path,
                            {"archetypes": set(), "rows": collections.Counter(), "points": 0, "colored": 0})
    if chunk.is_static:
        continue
    rb = chunk.to_record_batch()
    comps = {}
    for field in rb.schema:
        md = field.metadata or {}
        comp = md.get(b"rerun:component", field.name.encode()).decode()
        comps[comp] = rb.column(field.name)
        if md.get(b"rerun:kind") != b"data":
            continue
        e["rows"][comp] += len(comps[comp]) - comps[comp].null_count
        arch = md.get(b"rerun:archetype", b"").decode()
        if arch.startswith("rerun.archetypes."):
            arch = arch.rsplit(".", 1)[-1]
            e["archetypes"].add(arch + " (raw bytes)" if arch == "McapMessage" else arch)
        elif arch:
            e["archetypes"].add(arch + " (protobuf struct, not drawn)")
    pos, col = comps.get("Points3D:positions"), comps.get("Points3D:colors")
    if pos is not None:
        e["points"] += pa.compute.sum(pos.value_lengths()).as_py() or 0
    if col is not None:
        e["colored"] += pa.compute.sum(col.value_lengths()).as_py() or 0
    if chunk.entity_path in first_png:
        blob, media = comps.get("EncodedImage:blob"), comps.get("EncodedImage:media_type")
        times = comps["message_log_time"].cast(pa.int64()).to_pylist() if "message_log_time" in comps else []
        for i, t in enumerate(times):
            if media is not None and media[i].is_valid and media[i].values.to_pylist() != ["image/png"]:
                fail(f"rerun: {chunk.entity_path} @ {t}: media type {media[i].values.to_pylist()}, expected image/png")
            if blob is not None and blob[i].is_valid and t == first_png[chunk.entity_path][0]:
                e["first_blob"] = blob[i].values[0].values.to_numpy(zero_copy_only=False).tobytes()
    if chunk.entity_path == POINTS:
        if points_schema is None and pos is not None:
            points_schema = [f"{f.name}: {f.type}" for f in rb.schema]
        if (pos is not None or col is not None) and "message_log_time" not in comps:
            fail(f"rerun: {POINTS} has no message_log_time timeline; columns: {rb.schema.names}")
        times = comps["message_log_time"].cast(pa.int64()).to_pylist() if "message_log_time" in comps else []
        for i, t in enumerate(times):
            if pos is not None and pos[i].is_valid:
                positions[t].append(pos[i].values)
            if col is not None and col[i].is_valid:
                colors[t].append(col[i].values)

say(f"rerun entity {POINTS} columns: " + "; ".join(points_schema or ["(no Points3D:positions)"]))
e = entities.get(POINTS)
if e is None or e["rows"]["Points3D:positions"] == 0:
    fail(f"rerun: entity {POINTS} has no Points3D:positions "
         f"(entities with data: {sorted(k for k, v in entities.items() if v['rows'])})")
if e["rows"]["Points3D:colors"] == 0:
    fail(f"rerun: entity {POINTS} has Points3D:positions but no Points3D:colors")
for comp, rows in (("Points3D:positions", positions), ("Points3D:colors", colors)):
    if e["rows"][comp] != len(points_per_message):
        fail(f"rerun: {POINTS} has {e['rows'][comp]} rows of {comp}, MCAP has {len(points_per_message)} messages")
    for t, ns in mcap_n.items():
        got = sorted(len(r) for r in rows.get(t, []))
        if got != sorted(ns):
            fail(f"rerun: {POINTS} @ {t}: {comp} lengths {got} in Rerun, point counts {sorted(ns)} in MCAP")
p = next(r for r in positions[t0] if len(r) == len(xyz0))
c = next(r for r in colors[t0] if len(r) == len(xyz0))
p = p.flatten().to_numpy(zero_copy_only=False).astype(np.float32).reshape(-1, 3)
c = c.to_numpy(zero_copy_only=False).astype(np.uint32)
if not np.array_equal(p, xyz0, equal_nan=True):
    fail(f"rerun: {POINTS} @ {t0}: positions differ from the MCAP's x,y,z")
if not np.array_equal(c, rgba0):
    bad = int(np.argmax(c != rgba0))
    fail(f"rerun: {POINTS} @ {t0}: colour of point {bad} is {int(c[bad]):#010x} (0xRRGGBBAA) in Rerun, "
         f"{int(rgba0[bad]):#010x} from the MCAP's red,green,blue,alpha")
say(f"rerun {POINTS}: {e['rows']['Points3D:positions']} rows, {e['points']} points, {e['colored']} colours; "
    f"first cloud's positions and RGBA colours identical to the MCAP")

for topic in IMAGES:
    e = entities.get(topic)
    if e is None or e["rows"]["EncodedImage:blob"] != by_topic[topic]:
        fail(f"rerun: {topic}: {0 if e is None else e['rows']['EncodedImage:blob']} rows of EncodedImage:blob, "
             f"MCAP has {by_topic[topic]} messages")
    if e["rows"]["EncodedImage:media_type"] != by_topic[topic]:
        fail(f"rerun: {topic}: {e['rows']['EncodedImage:media_type']} rows of EncodedImage:media_type, "
             f"MCAP has {by_topic[topic]} messages")
    if e.get("first_blob") != first_png[topic][1]:
        fail(f"rerun: {topic} @ {first_png[topic][0]}: the EncodedImage blob differs from the MCAP's PNG")
    say(f"rerun {topic}: {by_topic[topic]} rows of EncodedImage (image/png); first blob identical to the MCAP's PNG")

# ---- table ---------------------------------------------------------------------
print()
print(f"{'topic':<28} {'messages':>8}  {'rerun entity':<28} {'archetypes':<50} {'rows':>5} {'points':>9} colours")
for topic in NEED_MESSAGES + NEED_CHANNEL:
    e = entities.get(topic)
    if e is None or not e["rows"]:
        shown = "-" if e is None else topic + " (channel info)"
        print(f"{topic:<28} {by_topic[topic]:>8}  {shown:<28} {'-':<50} {'-':>5} {'-':>9} -")
        continue
    arch = ",".join(sorted(e["archetypes"])) or "-"
    rows = max(e["rows"].values())
    has_points = e["rows"]["Points3D:positions"] > 0
    pts = e["points"] if has_points else "-"
    colours = ("yes" if e["colored"] == e["points"] else f"{e['colored']}/{e['points']}") if has_points else "-"
    print(f"{topic:<28} {by_topic[topic]:>8}  {topic:<28} {arch:<50} {rows:>5} {pts:>9} {colours}")
print()
print(f"check-viewers: OK: {MCAP} reads in mcap {importlib.metadata.version('mcap')} (CRCs validated) "
      f"and Rerun {rr.__version__} (Points3D with colours, PNG range images)")
PY

hint=" (stale output? run again with LOOMING_VIEWER_REBUILD=1)"
for mcap in "${mcaps[@]}"; do
  echo "check-viewers: == $mcap" >&2
  "$venv/bin/python" "$work/check.py" "$mcap" "$rrd" "$hint"
done

# 4. Lichtblick ------------------------------------------------------------------
if [[ -z ${LOOMING_LICHTBLICK_WEB:-} ]]; then
  echo "check-viewers: Lichtblick check skipped: set LOOMING_LICHTBLICK_WEB to a Lichtblick web build (docs/viewers.md)" >&2
  exit 0
fi
kit=${LOOMING_VIEWER_KIT:-$root/../shared/viewer-check}
shots=${LOOMING_LICHTBLICK_SHOTS:-target/lichtblick-shots}
[[ -f $kit/shoot.py ]] || die "$kit: no viewer kit there (shoot.py); set LOOMING_VIEWER_KIT"
[[ -x /usr/bin/chromium ]] || die "/usr/bin/chromium missing: apt-get install chromium"
if ! "$venv/bin/python" -c 'import playwright' 2>/dev/null; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check playwright==1.65.2 \
    || die "pip install playwright into $venv failed"
fi
cargo build --release -q
PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 "$venv/bin/python" scripts/check_lichtblick.py \
  "$kit" "$LOOMING_LICHTBLICK_WEB" target/release/looming "$shots" "${mcaps[@]}"
