# Included by scripts/bench.sh: the per-stage table of docs/performance.md
# from `looming process --json-summary` files (`annotation.stages`, seconds
# summed over a run's pairs), as milliseconds per pair.
STAGES = [
    ("range_images_s", "range images"),
    ("plane_fits_s", "plane fits"),
    ("cell_times_s", "cell times"),
    ("motion_estimate_s", "motion estimate"),
    ("renders_s", "renders"),
    ("cells_s", "per cell"),
    ("objects_s", "objects"),
    ("quality_and_events_s", "quality, events"),
    ("messages_s", "messages"),
]


def stage_table(named_summaries):
    """named_summaries: [(label, summary dict)]: a Markdown table, ms per pair."""
    head = "| run | pairs | " + " | ".join(label for _, label in STAGES) + " | engine |"
    lines = [head, "|" + "---|" * (len(STAGES) + 3)]
    for name, s in named_summaries:
        a = s["annotation"]
        pairs = max(1, a["pairs_annotated"])
        st = a.get("stages", {})
        cells = [f"{1000 * st.get(k, 0.0) / pairs:.1f}" for k, _ in STAGES]
        lines.append(f"| {name} | {pairs} | " + " | ".join(cells) + f" | {1000 * a['engine_s'] / pairs:.1f} |")
    lines.append("")
    lines.append("Wall ms per pair of each stage; the engine's stages (range images to per cell) "
                 "run beside the pair before's objects, quality, events and messages, so the "
                 "columns add up to more than the run's time per pair.")
    return "\n".join(lines)
