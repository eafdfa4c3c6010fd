"""Expressions of position written in a scene, such as an initial velocity
v_x = "exp(-25000*(x-0.03)**2)" [R §9.2].

An expression is parsed once into a syntax tree and checked: numbers, the scene's
parameters, the reference coordinates x, y, z (as many as the scene has dimensions), the
operators + - * / ** and the functions of FUNCTIONS; nothing else is accepted (no other
names, attributes, subscripts or calls), so evaluating a scene file runs no code of its
own. It is evaluated in IEEE double precision (numbers and parameters as numpy floats, so a
power overflows to inf at once instead of being raised exactly as a Python integer) on the
positions of a rank's particles; a value that is not a finite real number (an overflow, a
root of a negative number) is refused, naming the particle.
"""

from __future__ import annotations

import ast
import operator

import numpy as np

from parsph.errors import InputError

MAX_LENGTH = 300  # characters: bounds the nesting the parser sees
FUNCTIONS = {
    "exp": np.exp, "log": np.log, "sqrt": np.sqrt, "abs": np.abs, "sin": np.sin, "cos": np.cos,
    "tan": np.tan, "arctan": np.arctan, "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh,
    "minimum": np.minimum, "maximum": np.maximum,
}
ARGUMENTS = {"minimum": 2, "maximum": 2}  # the others take one
OPERATORS = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos,
}
COORDINATES = ("x", "y", "z")


class Field:
    """One checked expression of position."""

    def __init__(self, path: str, text: str, parameters: dict, dim: int, variables: tuple = None):
        """Raise InputError naming `path` if `text` is not an expression of numbers,
        `parameters`, the first `dim` coordinates (or the names `variables`, as ("t",)) and
        FUNCTIONS."""
        self.path, self.text = path, text
        self.parameters = dict(parameters)
        self.coordinates = COORDINATES[:dim] if variables is None else tuple(variables)
        if len(text) > MAX_LENGTH:
            raise InputError(f"{path}: the expression is {len(text)} characters long (at most {MAX_LENGTH})")
        try:
            self.tree = ast.parse(text, mode="eval")
        except SyntaxError:
            raise InputError(f"{path}: '{text}' is not an expression") from None
        self._check(self.tree.body)

    def _check(self, node) -> None:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            return
        if isinstance(node, ast.Name):
            if node.id in self.coordinates or node.id in self.parameters:
                return
            known = ", ".join(self.coordinates + tuple(self.parameters))
            raise InputError(f"{self.path}: unknown name '{node.id}' in '{self.text}' (known: {known})")
        if isinstance(node, ast.BinOp) and type(node.op) in OPERATORS:
            self._check(node.left)
            self._check(node.right)
            return
        if isinstance(node, ast.UnaryOp) and type(node.op) in OPERATORS:
            self._check(node.operand)
            return
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS \
                and not node.keywords and len(node.args) == ARGUMENTS.get(node.func.id, 1):
            for arg in node.args:
                self._check(arg)
            return
        raise InputError(f"{self.path}: '{self.text}' may use numbers, parameters, "
                         f"{', '.join(self.coordinates)}, + - * / ** and the functions "
                         f"{', '.join(FUNCTIONS)}")

    def __call__(self, X: np.ndarray, gid: np.ndarray) -> np.ndarray:
        """Values at the reference positions X (rows); raises InputError naming the first
        particle (global id `gid`) where the value is not finite."""
        names = {name: np.float64(value) for name, value in self.parameters.items()}
        names.update({c: X[:, k] for k, c in enumerate(self.coordinates)})

        def ev(node):
            if isinstance(node, ast.Constant):
                return np.float64(node.value)
            if isinstance(node, ast.Name):
                return names[node.id]
            if isinstance(node, ast.BinOp):
                return OPERATORS[type(node.op)](ev(node.left), ev(node.right))
            if isinstance(node, ast.UnaryOp):
                return OPERATORS[type(node.op)](ev(node.operand))
            return FUNCTIONS[node.func.id](*(ev(a) for a in node.args))

        with np.errstate(all="ignore"):
            try:
                value = np.broadcast_to(np.asarray(ev(self.tree.body), dtype=np.float64), (len(X),))
            except ArithmeticError as exc:  # on numbers alone: 1/0, 10.0**400
                raise InputError(f"{self.path}: '{self.text}' cannot be evaluated ({exc})") from None
        bad = ~np.isfinite(value)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            where = ", ".join(f"{c:.6g}" for c in X[k])
            raise InputError(f"{self.path} = '{self.text}' is {value[k]} at particle {int(gid[k])} ({where}): "
                             "not a finite real number")
        return value
