"""Every processing option a front-end offers, listed from the registries that define them.

A front-end (the console's page, a notebook, a script) renders these instead of writing the names
down: a new unwrapping method, correction or denoiser appears here as soon as its registry has it.
"""

from __future__ import annotations

from rig.pipeline.corrections import REGISTRY as CORRECTIONS
from rig.pipeline.plan import DEFAULT_CORRECTION
from rig.pipeline.stages import DENOISERS
from rig.pipeline.unwrapping import AUTO_DESCRIPTION
from rig.pipeline.unwrapping import REGISTRY as UNWRAPPERS


def available_options() -> dict[str, dict[str, object]]:
    """The ``--unwrap``, ``--correction`` and ``--denoise`` choices, each with its default and one line per choice.

    Returns
    -------
    dict
        ``{"unwrap": {"default": "auto", "choices": [{"name": ..., "description": ...}, ...]},
        "correction": {...}, "denoise": {...}}``, choices in registry order; JSON-serialisable.
    """
    unwrap = [{"name": "auto", "description": AUTO_DESCRIPTION}]
    unwrap += [{"name": m.name, "description": m.description} for m in UNWRAPPERS.values()]
    return {
        "unwrap": {"default": "auto", "choices": unwrap},
        "correction": {
            "default": DEFAULT_CORRECTION,
            "choices": [{"name": m.name, "description": m.description} for m in CORRECTIONS.values()],
        },
        "denoise": {
            "default": "none",
            "choices": [{"name": d.name, "description": d.description} for d in DENOISERS.values()],
        },
    }


def options_markdown() -> str:
    """docs/processing-options.md: a table per option, written from :func:`available_options`."""
    titles = {"unwrap": "`--unwrap`", "correction": "`--correction`", "denoise": "`--denoise`"}
    lines = [
        "# Processing options",
        "",
        "The choices of `rig process`, `rig batch` and the console, with one line each. This page is",
        "written from the registries (`rig.pipeline.registry.available_options`); regenerate it with",
        "`python -c 'from rig.pipeline.registry import options_markdown as m; print(m(), end=\"\")' > "
        "docs/processing-options.md`.",
    ]
    for key, option in available_options().items():
        lines += [
            "",
            f"## {titles[key]} (default `{option['default']}`)",
            "",
            "| name | what it does |",
            "| --- | --- |",
        ]
        choices = option["choices"]
        assert isinstance(choices, list)
        lines += [f"| `{choice['name']}` | {choice['description']} |" for choice in choices]
    return "\n".join(lines) + "\n"
