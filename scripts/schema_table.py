"""Print the Markdown tables of the shard format (the source of docs/shards.md's tables)."""

from colonbench.augment import AugmentConfig
from colonbench.datagen.config import describe as describe_config
from colonbench.shards.schema import (ATTRIBUTES, COLON_ATTRIBUTES, COLON_FIELDS, COLON_OPTIONAL_ATTRIBUTES,
                                      HEATMAP_FIELDS, OPTIONAL_ATTRIBUTES, describe)


def tables() -> str:
    out = ["| dataset | shape | dtype | unit | frame | meaning |", "|---|---|---|---|---|---|"]
    out += [f"| {p} | {s} | {d} | {u} | {f} | {m} |" for p, s, d, u, f, m in describe()]
    out += ["", "| file attribute | meaning |", "|---|---|"]
    out += [f"| `{k}` | {v} |" for k, v in ATTRIBUTES.items()]
    out += [f"| `{k}` (optional) | {v} |" for k, v in OPTIONAL_ATTRIBUTES.items()]
    out += ["", "Format 1 (read, no longer written) stored two heatmaps where format 2 stores `s0`, `s1`, `c`, and "
            "float32 points in every split:", "",
            "| dataset | shape | dtype | unit | frame | meaning |", "|---|---|---|---|---|---|"]
    out += [f"| {p} | {s} | {d} | {u} | {f} | {m} |" for p, s, d, u, f, m in describe(HEATMAP_FIELDS)]
    out += ["", "Whole-colon shards (`task: colon` manifests, `colonbench.shards.colonshard`):", "",
            "| dataset | shape | dtype | unit | frame | meaning |", "|---|---|---|---|---|---|"]
    out += [f"| {p} | {s} | {d} | {u} | {f} | {m} |" for p, s, d, u, f, m in describe(COLON_FIELDS)]
    out += ["", "| whole-colon file attribute | meaning |", "|---|---|"]
    out += [f"| `{k}` | {v} |" for k, v in COLON_ATTRIBUTES.items()]
    out += [f"| `{k}` (optional) | {v} |" for k, v in COLON_OPTIONAL_ATTRIBUTES.items()]
    out += ["", "| augmentation field | default | limits | unit | meaning |", "|---|---|---|---|---|"]
    out += [f"| `{n}` | {d} | {lim} | {u} | {m} |" for n, d, lim, u, m in describe_config(AugmentConfig)]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    print(tables())
