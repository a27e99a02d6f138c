"""Print the Markdown tables of every generator config field (the source of docs/datagen.md's tables)."""

from colonbench.datagen.config import CONFIG_CLASSES, describe


def tables() -> str:
    out = []
    for section, cls in CONFIG_CLASSES.items():
        out.append(f"### `{section}` ({cls.__name__}): {cls.__doc__.strip()}\n")
        out.append("| field | default | limits | unit | meaning |")
        out.append("|---|---|---|---|---|")
        for name, default, limits, unit, doc in describe(cls):
            out.append(f"| `{name}` | {default} | {limits} | {unit} | {doc} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(tables())
