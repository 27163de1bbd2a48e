"""One source of defaults: every family, sampler and scene reads the keys its YAML declares, with no literal
fallback in code (a fallback is a second default that can disagree with the YAML silently)."""

import ast
import inspect
import os
import textwrap

import pytest

from ddfbench import sampling
from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.models import available_families, load_family
from ddfbench.render import scene as scene_module
from ddfbench.render.scene import declared_scene, parse_scene


def family_sources(name: str) -> dict[str, str]:
    """label -> source of the code family `name` runs: its module (every module of its package where the family
    is one) and the classes it inherits from within ddfbench.models."""
    cls = load_family(name)
    package = os.path.join(os.path.dirname(inspect.getsourcefile(load_family)), name)
    files = ([os.path.join(package, f) for f in sorted(os.listdir(package)) if f.endswith(".py")]
             if os.path.isdir(package) else [inspect.getsourcefile(cls)])
    out = {os.path.basename(f): open(f).read() for f in files}
    for base in cls.__mro__[1:]:
        if base.__module__.startswith("ddfbench.models") and inspect.getsourcefile(base) not in files:
            out[base.__name__] = textwrap.dedent(inspect.getsource(base))
    return out


def _reads_cfg(node: ast.AST) -> bool:
    """Whether node is a config object: a name or attribute called cfg (cfg, self.cfg, rep.cfg)."""
    return (isinstance(node, ast.Name) and node.id == "cfg") or (isinstance(node, ast.Attribute) and node.attr == "cfg")


def _cfg_get(node: ast.AST) -> bool:
    """Whether node is a call cfg.get(...) on a config object."""
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
            and _reads_cfg(node.func.value))


def config_reads(source: str, label: str) -> tuple[set[str], list[str]]:
    """(keys read as cfg["key"], every fallback as 'label:line key': cfg.get("key", fallback) and
    cfg.get("key") or fallback) in source."""
    keys, fallbacks = set(), []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BoolOp) and isinstance(node.op, ast.Or) and _cfg_get(node.values[0]):
            fallbacks.append(f"{label}:{node.lineno} {ast.unparse(node.values[0].args[0])}")
        if isinstance(node, ast.Subscript) and _reads_cfg(node.value) and isinstance(node.slice, ast.Constant):
            keys.add(node.slice.value)
        if _cfg_get(node) and len(node.args) == 2:
            fallbacks.append(f"{label}:{node.lineno} {ast.unparse(node.args[0])}")
    return keys, fallbacks


def test_the_reader_finds_reads_and_fallbacks():
    source = ("def f(self, cfg):\n    a = self.cfg['lr']\n    b = cfg.get('batch', 8192)\n    c = cfg.get('x')\n"
              "    d = rep.cfg.get('width') or 64\n")
    keys, fallbacks = config_reads(source, "family.py")
    assert keys == {"lr"} and sorted(fallbacks) == ["family.py:3 'batch'", "family.py:5 'width'"]


@pytest.mark.parametrize("family", available_families())
def test_a_family_reads_only_declared_keys_without_fallbacks(family):
    declared = set(plugins.defaults("model", family))
    read, fallbacks = set(), []
    for label, source in family_sources(family).items():
        keys, found = config_reads(source, label)
        read |= keys
        fallbacks += found
    assert fallbacks == []
    assert read - declared == set(), f"conf/model/{family}.yaml does not declare what the code reads"


def test_samplers_and_scenes_have_no_fallbacks():
    folders = [os.path.dirname(inspect.getsourcefile(sampling))]
    files = [os.path.join(f, n) for f in folders for n in os.listdir(f) if n.endswith(".py")]
    files.append(inspect.getsourcefile(scene_module))
    assert [hit for path in sorted(files) for hit in config_reads(open(path).read(), os.path.basename(path))[1]] == []


def test_a_scene_takes_the_declared_values_of_what_it_leaves_out():
    base = plugins.defaults("scene", "depth")
    scene = parse_scene({"outputs": ["depth"], "width": 7})
    assert scene.width == 7 and scene.height == base["height"]
    assert scene.repeats == base["timing"]["repeats"] and len(scene.cameras) == base["cameras"]["n"]
    assert declared_scene({"cameras": {"n": 1}})["cameras"]["radius"] == base["cameras"]["radius"]


@pytest.mark.parametrize("cfg, named", [({"bogus": 3}, "scene.bogus"), ({"cameras": {"nn": 1}}, "scene.cameras.nn"),
                                        ({"timing": {"repeat": 2}}, "scene.timing.repeat"),
                                        ({"cameras": 3}, "scene.cameras=3")])
def test_a_scene_key_nothing_declares_is_refused_by_name(cfg, named):
    with pytest.raises(InputError, match=f"^{named}"):
        parse_scene({"outputs": ["depth"], **cfg})
