"""The type stubs of the compiled module name what it has, and every public function of the
package has a docstring."""

import ast
import inspect
from pathlib import Path

import exid
from exid import _exid


def stub_names():
    tree = ast.parse((Path(exid.__file__).parent / "_exid.pyi").read_text())
    top, robot = set(), set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            top.add(node.name)
        elif isinstance(node, (ast.AnnAssign)) and isinstance(node.target, ast.Name):
            top.add(node.target.id)
        if isinstance(node, ast.ClassDef) and node.name == "Robot":
            robot = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
    return top, robot


def test_stubs_match_the_module():
    top, robot = stub_names()
    public = {n for n in dir(_exid) if not n.startswith("_")} | {"__version__"}
    assert public == top - {"ArrayLike", "Array"}
    methods = {n for n in dir(_exid.Robot) if not n.startswith("_")} | {"__init__"}
    assert methods == robot


def test_public_api_is_documented():
    for name in exid.__all__:
        obj = getattr(exid, name)
        if inspect.isfunction(obj) or inspect.isclass(obj):
            assert inspect.getdoc(obj), name
    for name, member in inspect.getmembers(exid.Robot):
        if not name.startswith("_") and (inspect.isfunction(member) or isinstance(member, property)):
            assert inspect.getdoc(member), name
