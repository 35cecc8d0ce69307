"""The type stubs (python/robocal/__init__.pyi) describe the module as built: every public name,
every class's public members, and each function's keyword arguments, in both directions."""

import ast
import inspect
import pathlib

import robocal

STUBS = pathlib.Path(__file__).resolve().parents[1] / "python" / "robocal" / "__init__.pyi"


def stub_tree():
    return ast.parse(STUBS.read_text(encoding="utf-8"))


def test_every_public_name_has_a_stub_and_every_stub_exists():
    tree = stub_tree()
    stubbed = {n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    stubbed |= {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    public = set(robocal.__all__)
    assert public <= stubbed, sorted(public - stubbed)
    assert stubbed <= public | {"ArrayLike"}, sorted(stubbed - public)


def test_class_members_match():
    checked = 0
    for node in stub_tree().body:
        if not isinstance(node, ast.ClassDef):
            continue
        cls = getattr(robocal, node.name)
        stubbed = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        stubbed |= {n.target.id for n in node.body if isinstance(n, ast.AnnAssign)}
        if issubclass(cls, BaseException):
            assert stubbed <= {"field", "reasons", "kind"}, node.name
            continue
        public = {m for m in dir(cls) if not m.startswith("_")}
        assert stubbed == public, (node.name, sorted(stubbed ^ public))
        checked += len(public)
    assert checked > 60, checked


def test_function_keywords_match():
    for node in stub_tree().body:
        if not isinstance(node, ast.FunctionDef):
            continue
        args = node.args
        stubbed = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
        actual = list(inspect.signature(getattr(robocal, node.name)).parameters)
        assert stubbed == actual, node.name
