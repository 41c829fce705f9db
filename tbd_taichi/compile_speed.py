"""Less Python work in Taichi's kernel front end, which runs in every process even when the offline cache holds
the compiled kernels (Taichi 1.7 keys its cache on the kernel's IR, so it rebuilds that IR from the Python AST
first).

Four costs of Taichi 1.7's front end that do not change what it builds:

* **Source positions.** For every AST node it formats a source excerpt with a caret line through
  ``textwrap.TextWrapper`` (``ASTTransformerContext.get_pos_info``), about half the front end's time, although
  the text is shown only in a compile error.  :func:`brief_position` gives the file, line and function instead.
* **Source parsing.** Each ``ti.func`` is inlined by re-reading its source through ``inspect`` and re-tokenising
  it at every call site (``kernel_impl._get_tree_and_ctx``).  :func:`cached_tree_and_ctx` keeps each function's
  source text and parses only that (the tree must be fresh: the transformer writes into its nodes).
* **Source lookup.** Taichi reads each function's source through ``inspect.getsourcelines``, which searches
  every loaded module for the function's file and tokenises the file from the function's first line to find its
  end.  :func:`source_lines` parses each file once with :mod:`ast` and takes the function's lines from
  ``linecache`` (functions defined elsewhere, as in IPython, keep Taichi's lookup).
* **Declaration tracebacks.** Every field, SNode and ndarray records the whole Python stack, formatted, for an
  error message that names where it was declared (``util.get_traceback``: 0.1–0.2 s for the 400–600 fields of a
  tracker).  :func:`brief_traceback` keeps the three innermost frames of that stack.
* **Class detection.** ``@ti.kernel`` asks whether it decorates a method by reading the caller's source line
  through ``inspect.getframeinfo``, which searches every loaded module for the frame's file, at each decoration
  (import time).  :func:`inside_class` reads the same line through ``linecache``.

:func:`install` applies all five unless debug mode is on (then Taichi's full messages are kept); it checks the private
names it replaces first and leaves Taichi as it is where they differ, so a Taichi upgrade costs speed, not
correctness.  ``tests/test_compile_speed.py`` checks that the names exist and that the kernels are unchanged.
The measured effect is in ``docs/performance-history.md`` (start-up), today's figures in ``docs/performance.md``."""
from __future__ import annotations

import ast
import inspect
import linecache
import sys
import textwrap
import traceback

_SOURCES: dict = {}  # function object -> (file, lines, first line, dedented text)
_FUNCTION_ENDS: dict = {}  # file -> {first line of a def with its decorators: last line}
TRACEBACK_MODULES = ("impl", "snode", "matrix", "_ndarray")  # taichi.lang modules that import get_traceback
TRACEBACK_FRAMES = 3  # innermost frames kept by brief_traceback
_ORIGINAL: dict = {}  # name -> Taichi's own function, while installed


def taichi_front_end():
    """(ASTTransformerContext class, kernel_impl module) of this Taichi, or None where either lacks a name this
    module replaces or reads."""
    try:
        from taichi.lang import kernel_impl
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    except ImportError:  # pragma: no cover - another Taichi layout
        return None
    needed = (hasattr(ASTTransformerContext, "get_pos_info"), hasattr(kernel_impl, "_get_tree_and_ctx"),
              hasattr(kernel_impl, "_get_global_vars"), hasattr(kernel_impl, "ASTTransformerContext"),
              hasattr(kernel_impl, "_inside_class"), hasattr(kernel_impl, "_KERNEL_CLASS_STACKFRAME_STMT_RES"),
              hasattr(kernel_impl, "getsourcelines"), hasattr(kernel_impl, "getsourcefile"))
    if not all(needed) or not all(hasattr(module, "get_traceback") for module in traceback_modules()):
        return None
    params = list(inspect.signature(kernel_impl._get_tree_and_ctx).parameters)
    if params != ["self", "excluded_parameters", "is_kernel", "arg_features", "args", "ast_builder",
                  "is_real_function"]:
        return None
    return ASTTransformerContext, kernel_impl


def traceback_modules() -> list:
    """The taichi.lang modules whose ``get_traceback`` name :func:`install` replaces."""
    import importlib

    return [importlib.import_module(f"taichi.lang.{name}") for name in TRACEBACK_MODULES]


def brief_traceback(stacklevel: int = 1) -> str:
    """``util.get_traceback``: the stack above the caller's ``stacklevel`` frames, formatted; only its
    TRACEBACK_FRAMES innermost frames."""
    frames = traceback.extract_stack(sys._getframe(stacklevel + 1), limit=TRACEBACK_FRAMES)
    return "".join(traceback.format_list(frames))


def function_ends(file: str) -> dict:
    """{first line (its first decorator's, else its ``def``'s): last line} of every function in ``file``, the file
    parsed once; {} where it is not Python source."""
    ends = _FUNCTION_ENDS.get(file)
    if ends is None:
        ends = {}
        try:
            tree = ast.parse("".join(linecache.getlines(file)))
        except (SyntaxError, ValueError):
            tree = None
        statements = list(tree.body) if tree is not None else []
        while statements:  # statements only: a def is never inside an expression
            node = statements.pop()
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                ends[first] = node.end_lineno
            for field in ("body", "orelse", "finalbody", "handlers", "cases"):
                statements.extend(getattr(node, field, ()))
        _FUNCTION_ENDS[file] = ends
    return ends


def source_lines(func) -> tuple:
    """(file, lines, first line number) of ``func``'s source with its decorators, as ``inspect.getsourcefile`` and
    ``getsourcelines`` give them, from the file's parse (:func:`function_ends`); Taichi's own lookup where the
    file is not at hand."""
    from taichi.lang import kernel_impl

    code = getattr(inspect.unwrap(func), "__code__", None)
    if code is not None:
        first = code.co_firstlineno
        last = function_ends(code.co_filename).get(first)
        if last is not None:
            return code.co_filename, linecache.getlines(code.co_filename)[first - 1:last], first
    return (kernel_impl.getsourcefile(func),) + tuple(kernel_impl.getsourcelines(func))


def inside_class(level_of_class_stackframe: int) -> bool:
    """``kernel_impl._inside_class``: whether the frame that many levels up is executing a class body (its current
    line starts ``class`` or ``@…data_oriented``), its line read through ``linecache``."""
    from taichi.lang import kernel_impl

    try:
        frame = sys._getframe(level_of_class_stackframe)  # counted from this frame, as Taichi counts it
    except ValueError:
        return False
    line = linecache.getline(frame.f_code.co_filename, frame.f_lineno, frame.f_globals).strip()
    return any(pattern.match(line) for pattern in kernel_impl._KERNEL_CLASS_STACKFRAME_STMT_RES)


def brief_position(ctx, node) -> str:
    """The position Taichi prefixes to a compile error: file, line and function, without the source excerpt."""
    return f'File "{ctx.file}", line {node.lineno + ctx.lineno_offset}, in {ctx.func.func.__name__}:\n'


def function_source(func) -> tuple:
    """(file, source lines as Taichi normalises them, first line number, dedented text) of ``func``, read once."""
    entry = _SOURCES.get(func)
    if entry is None:
        file, lines, start = source_lines(func)
        lines = [textwrap.fill(line, tabsize=4, width=9999) for line in lines]
        entry = (file, lines, start, textwrap.dedent("\n".join(lines)))
        _SOURCES[func] = entry
    return entry


def cached_tree_and_ctx(self, excluded_parameters=(), is_kernel=True, arg_features=None, args=None,
                        ast_builder=None, is_real_function=False):
    """``kernel_impl._get_tree_and_ctx`` with the source read once per function (same tree, same context)."""
    from taichi.lang import kernel_impl

    file, src, start_lineno, text = function_source(self.func)
    tree = ast.parse(text)
    tree.body[0].decorator_list = []
    global_vars = kernel_impl._get_global_vars(self.func)
    if is_kernel or is_real_function:
        for i in self.template_slot_locations:  # inject template parameters into globals
            global_vars[self.arguments[i].name] = args[i]
    return tree, kernel_impl.ASTTransformerContext(
        excluded_parameters=excluded_parameters, is_kernel=is_kernel, func=self, arg_features=arg_features,
        global_vars=global_vars, argument_data=args, src=src, start_lineno=start_lineno, file=file,
        ast_builder=ast_builder, is_real_function=is_real_function)


def install(debug: bool = False) -> bool:
    """Apply the three savings (not in ``debug`` mode); False where this Taichi's front end differs (nothing changed)."""
    if debug:
        uninstall()
        return False
    front = taichi_front_end()
    if front is None:
        return False
    context, kernel_impl = front
    if not _ORIGINAL:
        _ORIGINAL["get_pos_info"] = context.get_pos_info
        _ORIGINAL["_get_tree_and_ctx"] = kernel_impl._get_tree_and_ctx
        _ORIGINAL["_inside_class"] = kernel_impl._inside_class
        _ORIGINAL["get_traceback"] = traceback_modules()[0].get_traceback
    for module in traceback_modules():
        module.get_traceback = brief_traceback
    context.get_pos_info = brief_position
    kernel_impl._get_tree_and_ctx = cached_tree_and_ctx
    kernel_impl._inside_class = inside_class
    return True


def uninstall() -> None:
    """Taichi's own front end again."""
    if not _ORIGINAL:
        return
    context, kernel_impl = taichi_front_end() or (None, None)
    if context is not None:
        context.get_pos_info = _ORIGINAL["get_pos_info"]
        kernel_impl._get_tree_and_ctx = _ORIGINAL["_get_tree_and_ctx"]
        kernel_impl._inside_class = _ORIGINAL["_inside_class"]
        for module in traceback_modules():
            module.get_traceback = _ORIGINAL["get_traceback"]
    _ORIGINAL.clear()


def installed() -> bool:
    """Whether :func:`install` is in effect."""
    return bool(_ORIGINAL)
