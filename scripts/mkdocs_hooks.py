"""The documentation site's build hooks (``hooks:`` in mkdocs.yml), and what they generate.

- The configuration reference: ``<!-- config-reference -->`` in a page becomes one table per config
  section, every key with its type, its default and what it means, read from the dataclasses of
  :mod:`dospcot.config` (defaults from the fields, meanings from each class's ``:param`` lines; the
  ``[dqn]`` keys that come from stable-baselines3's ``DQN`` take SB3's own descriptions). Nothing is
  typed twice, so the page cannot drift from the code.
- The API reference's coverage: every module of the package must be rendered by some page under
  ``docs/api/`` (a ``::: module`` line), and every public name of those modules must have a
  docstring. Either gap is logged as a warning, which ``mkdocs build --strict`` turns into a failed
  build.

``python scripts/mkdocs_hooks.py`` prints the configuration reference and the gaps, without mkdocs.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import logging
import math
import pkgutil
import re
import shutil
from pathlib import Path
from typing import Any

LOG = logging.getLogger("mkdocs.plugins.dospcot")
"""A logger under mkdocs's own, so that ``--strict`` counts its warnings."""
ROOT = Path(__file__).resolve().parents[1]
API_PAGES = ROOT / "docs" / "api"
CONFIG_MARK = "<!-- config-reference -->"
PACKAGES = ("dospcot", "dospcot.envs", "dospcot.policies", "dospcot.lab")
"""The package and the sub-packages that live in folders of their own (``envs/``, ``policies/``,
``lab/``)."""
NOT_API = {"dospcot.__main__", "dospcot.cli", "dospcot.cli.__main__", "dospcot.cli.commands",
           "dospcot.cli.parser"}  # fmt: skip
"""Modules that are a command, not an API: ``dospcot --help`` and the guide document them."""
KNOWN_GAPS = {
    "dospcot.envs.gridworld.GridLayout.goal",
    "dospcot.envs.gridworld.GridLayout.size",
    "dospcot.envs.tabular.TabularMDP.n_actions",
    "dospcot.envs.tabular.TabularMDP.n_states",
    "dospcot.policies.tabular.agents.TabularAgents.n_slots",
}
"""Public names without a docstring when this check was written, in modules another change owns:
listed so that the build holds while they are documented there. Any other undocumented name fails
the build; an entry here that has since got its docstring is only reported."""


DQN_NOTES = {
    "n_steps": "n-step returns: each replayed sample is a window of up to n steps of one env, every reward "
    "in it relabelled from the run's reward table when it is sampled (SB3's argument, read by dospcot's "
    "relabelling buffer; [the agent](agent.md) says where a window ends).",
}
"""``[dqn]`` keys whose meaning in dospcot is not what SB3's docstring says."""


# --- the configuration reference --------------------------------------------------------------------


def _sphinx_to_markdown(text: str) -> str:
    """A docstring fragment as one line of markdown: roles and double backticks as code spans."""
    text = re.sub(r":\w+:`~?([^`]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", text)
    text = text.replace("``", "`")
    return " ".join(text.split()).replace("|", "\\|")


def param_docs(doc: str | None) -> dict[str, str]:
    """The ``:param name: text`` entries of a docstring, each text on one line."""
    end = r"(?=\n\s*:(?:param|raises|returns?|rtype|type|ivar|cvar)\b|\n\s*\n|\Z)"
    entries = re.findall(r":param (\w+):(.*?)" + end, doc or "", flags=re.DOTALL)
    return {name: _sphinx_to_markdown(text) for name, text in entries}


def toml_value(value: Any) -> str:
    """A default as it would be written in a config."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if isinstance(value, tuple | list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _type_name(annotation: Any) -> str:
    if isinstance(annotation, str):
        return annotation
    return annotation.__name__ if isinstance(annotation, type) else str(annotation)


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    return field.default_factory()  # type: ignore[misc]


def section_tables(cls: type, key: str, extra_docs: dict[str, str] | None = None) -> list[str]:
    """The reference of one config section (the dataclass ``cls``, read from ``[key]``), then of its
    sub-sections; the top level's keys where ``key`` is empty."""
    docs = {**(extra_docs or {}), **param_docs(cls.__doc__)}
    title = f"`[{key}]`" if key else "Top-level keys"
    lines = [f"### {title}", "", f"`{cls.__module__}.{cls.__name__}`", ""]
    summary = _sphinx_to_markdown((cls.__doc__ or "").strip().split("\n\n")[0])
    lines += [summary, "", "| key | type | default | meaning |", "|---|---|---|---|"]
    nested = []
    for field in dataclasses.fields(cls):
        default = _default(field)
        if dataclasses.is_dataclass(default):
            nested.append((type(default), f"{key}.{field.name}" if key else field.name))
            continue
        meaning = docs.get(field.name, "")
        lines.append(f"| `{field.name}` | `{_type_name(field.type)}` | `{toml_value(default)}` | {meaning} |")
    for note, mapping in (
        ("Set elsewhere, not in this section", getattr(cls, "set_elsewhere", {})),
        (
            "Renamed keys (a config with the old name is refused, naming the new one)",
            getattr(cls, "renamed_keys", {}),
        ),
    ):
        if mapping:
            lines += ["", f"{note}: " + "; ".join(f"`{k}`: {v}" for k, v in mapping.items()) + "."]
    lines.append("")
    for nested_cls, nested_key in nested:
        lines += section_tables(nested_cls, nested_key)
    return lines


def config_reference() -> str:
    """Every key of a ``dospcot train`` config and of a paper-protocol config, with its default."""
    from stable_baselines3 import DQN

    from dospcot.config.run_configs import PaperConfig, TrainConfig

    sb3 = {name: f"stable-baselines3's: {text}" for name, text in param_docs(DQN.__doc__).items()}
    sb3.update(DQN_NOTES)
    lines = ["## A training config (`dospcot train`)", ""]
    for field in dataclasses.fields(TrainConfig):
        default = _default(field)
        if dataclasses.is_dataclass(default):
            lines += section_tables(type(default), field.name, sb3 if field.name == "dqn" else None)
    top = [f for f in dataclasses.fields(TrainConfig) if not dataclasses.is_dataclass(_default(f))]
    top_cls = dataclasses.make_dataclass("TrainConfig", [(f.name, f.type, f) for f in top])
    top_cls.__module__, top_cls.__doc__ = TrainConfig.__module__, TrainConfig.__doc__
    lines[2:2] = section_tables(top_cls, "")
    lines += ['## A paper-protocol config (`task = "paper"`)', ""]
    paper = [f for f in dataclasses.fields(PaperConfig) if not dataclasses.is_dataclass(_default(f))]
    paper_cls = dataclasses.make_dataclass("PaperConfig", [(f.name, f.type, f) for f in paper])
    paper_cls.__module__, paper_cls.__doc__ = PaperConfig.__module__, PaperConfig.__doc__
    lines += section_tables(paper_cls, "")
    lines += section_tables(type(PaperConfig().tabular), "tabular")
    return "\n".join(lines)


# --- the API reference's coverage -------------------------------------------------------------------


def package_modules() -> list[str]:
    """Every module of the package, by import name, less those that are not an API."""
    names: list[str] = []

    def walk(name: str) -> None:
        names.append(name)
        module = importlib.import_module(name)
        for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
            if not info.name.startswith("_") and f"{name}.{info.name}" not in PACKAGES:
                walk(f"{name}.{info.name}")

    for package in PACKAGES:
        walk(package)
    return [name for name in names if name not in NOT_API]


def rendered_modules(pages: Path = API_PAGES) -> set[str]:
    """The modules the API pages render (their ``::: module`` lines)."""
    return {
        match.group(1)
        for page in pages.glob("*.md")
        for match in re.finditer(r"^::: ([\w.]+)", page.read_text(), flags=re.MULTILINE)
    }


def _protocol_docs() -> dict[str, str]:
    """Methods documented on the protocols a task adapter implements: an implementation inherits the
    protocol's docstring as a subclass inherits its base's."""
    from dospcot.core.cotraining_run import TaskAdapter

    return {name: inspect.getdoc(member) or "" for name, member in vars(TaskAdapter).items()}


def public_names(module_name: str) -> list[tuple[str, Any]]:
    """A module's public names (its ``__all__``, else the classes and functions it defines and does
    not prefix with ``_``) and the public methods and properties each such class defines."""
    module = importlib.import_module(module_name)
    names = getattr(module, "__all__", None) or [
        name
        for name, value in vars(module).items()
        if not name.startswith("_")
        and (inspect.isclass(value) or inspect.isfunction(value))
        and getattr(value, "__module__", None) == module_name
    ]
    found = []
    for name in names:
        value = getattr(module, name)
        found.append((f"{module_name}.{name}", value))
        if inspect.isclass(value) and value.__module__ == module_name:
            for member, raw in vars(value).items():
                function = raw.fget if isinstance(raw, property) else getattr(raw, "__func__", raw)
                if not member.startswith("_") and inspect.isfunction(function):
                    found.append((f"{module_name}.{name}.{member}", getattr(value, member)))
    return found


def documentation_gaps() -> tuple[list[str], list[str]]:
    """The modules no API page renders, and the public names without a docstring (less the known
    gaps)."""
    modules = package_modules()
    missing_pages = sorted(set(modules) - rendered_modules())
    protocol = _protocol_docs()
    undocumented = []
    for module_name in modules:
        if not (importlib.import_module(module_name).__doc__ or "").strip():
            undocumented.append(module_name)
        for name, value in public_names(module_name):
            doc = inspect.getdoc(value)  # a method without its own docstring inherits its base's
            if not (doc or "").strip() and not protocol.get(name.rsplit(".", 1)[1]):
                undocumented.append(name)
    return missing_pages, undocumented


API_SOURCE = ROOT / "build" / "api-source"
"""The package as it imports (``dospcot/`` with ``envs/``, ``policies/`` and ``lab/`` inside), for the API
reference's static analysis; mkdocs.yml points mkdocstrings here."""


def lay_out_api_source() -> Path:
    """Build :data:`API_SOURCE`: symbolic links to every entry of ``dospcot/``, and to ``envs/``,
    ``policies/`` and ``lab/`` as ``dospcot/envs``, ``dospcot/policies`` and ``dospcot/lab``, as
    pyproject's ``package-dir`` maps them."""
    package = API_SOURCE / "dospcot"
    if API_SOURCE.exists():
        shutil.rmtree(API_SOURCE)
    package.mkdir(parents=True)
    for entry in (ROOT / "dospcot").iterdir():
        if entry.name != "__pycache__":
            (package / entry.name).symlink_to(entry)
    for name in ("envs", "policies", "lab"):
        (package / name).symlink_to(ROOT / name)
    return package


# --- mkdocs hooks ------------------------------------------------------------------------------------


def on_startup(**kwargs: Any) -> None:
    """Lay out the package for the API reference before mkdocstrings reads its search paths."""
    lay_out_api_source()


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    """Fill the configuration reference in."""
    if CONFIG_MARK in markdown:
        markdown = markdown.replace(CONFIG_MARK, config_reference())
    return markdown


def on_post_build(config: Any, **kwargs: Any) -> None:
    """Warn about every module no API page renders and every undocumented public name."""
    missing_pages, undocumented = documentation_gaps()
    for module in missing_pages:
        LOG.warning(f"API reference: no page under docs/api/ renders {module} (add a '::: {module}' line)")
    for name in sorted(set(undocumented) - KNOWN_GAPS):
        LOG.warning(f"API reference: {name} is public and has no docstring")
    for name in sorted(KNOWN_GAPS - set(undocumented)):
        LOG.info(f"API reference: {name} has its docstring now; drop it from KNOWN_GAPS")


if __name__ == "__main__":
    print(config_reference())
    pages, names = documentation_gaps()
    print("\nmodules without a page:", pages or "none")
    print("undocumented names:", sorted(set(names) - KNOWN_GAPS) or "none")
