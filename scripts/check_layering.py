#!/usr/bin/env python3
"""Checks evloc's layering: every #include and every CMake link against the allowed-dependency
table of docs/architecture.md (the rows between the `layering-table` markers).

Usage: check_layering.py [--root DIR] [--self-test]

A module is a folder named in the table; a file belongs to the module with the longest matching
folder. Module A may use module B when B is A itself or is reachable from A through the "may use"
column (the relation is transitive). Test code (files whose name contains `_test`, and files
under a `testing/` or `fuzz/` folder, and the CMake targets made by evloc_add_test,
evloc_add_fuzzer and the `*_testing` libraries) may also use the modules in the "its tests may
also use" column. Generated protobuf headers (`evloc/*.pb.h`) belong to `proto`.

Exit 0 when there is no violation; 1 with one line per violation otherwise (file:line, the
edge, and what the table allows); 2 for a malformed table. --self-test adds an upward include
and an upward link in memory and exits 0 only when both are reported.
"""

import argparse
import os
import re
import subprocess
import sys

TABLE_BEGIN = "<!-- layering-table-begin -->"
TABLE_END = "<!-- layering-table-end -->"
SOURCE_SUFFIXES = (".h", ".cc")
CMAKE_NAMES = ("CMakeLists.txt",)
CMAKE_SUFFIXES = (".cmake",)


class TableError(Exception):
    pass


def read_table(root):
    path = os.path.join(root, "docs", "architecture.md")
    with open(path, encoding="utf-8") as handle:
        text = handle.read()
    if TABLE_BEGIN not in text or TABLE_END not in text:
        raise TableError(f"{path}: the markers {TABLE_BEGIN} and {TABLE_END} are missing")
    block = text.split(TABLE_BEGIN, 1)[1].split(TABLE_END, 1)[0]
    uses = {}
    test_uses = {}
    for number, line in enumerate(block.splitlines(), 1):
        line = line.strip()
        if not line.startswith("|") or line.startswith("|---") or line.startswith("| module"):
            continue
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        if len(cells) != 3:
            raise TableError(f"{path}: layering table row '{line}' does not have 3 cells")
        module = cells[0].strip("`")

        def names(cell):
            # The module names are the back-quoted words; anything else is a comment.
            return re.findall(r"`([^`]+)`", cell)

        if module in uses:
            raise TableError(f"{path}: module {module} is listed twice in the layering table")
        uses[module] = names(cells[1])
        test_uses[module] = names(cells[2])
    for module, targets in list(uses.items()) + list(test_uses.items()):
        for target in targets:
            if target not in uses:
                raise TableError(f"{path}: module {module} names '{target}', which has no row")
    return uses, test_uses


def closure(uses, start_modules):
    seen = set()
    stack = list(start_modules)
    while stack:
        module = stack.pop()
        if module in seen:
            continue
        seen.add(module)
        stack.extend(uses[module])
    return seen


def find_cycle(uses):
    for module in uses:
        if module in closure(uses, uses[module]):
            return module
    return None


def module_of(path, modules):
    best = None
    for module in modules:
        if path == module or path.startswith(module + "/"):
            if best is None or len(module) > len(best):
                best = module
    return best


def is_test_path(path):
    name = os.path.basename(path)
    parts = path.split("/")
    return "_test" in name or "testing" in parts[:-1] or "fuzz" in parts[:-1]


def list_files(root):
    try:
        output = subprocess.run(["git", "-C", root, "ls-files"], check=True,
                                capture_output=True, text=True).stdout
        return [line for line in output.splitlines() if line]
    except (OSError, subprocess.CalledProcessError):
        files = []
        for directory, subdirs, names in os.walk(root):
            subdirs[:] = [d for d in subdirs if not d.startswith(".") and not d.startswith("build")]
            for name in names:
                files.append(os.path.relpath(os.path.join(directory, name), root))
        return files


INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def include_module(include, modules):
    if include.startswith("evloc/") and include.endswith(".pb.h"):
        return "proto"
    return module_of(include, modules)


def scan_includes(root, files, modules):
    """Yields (file, line, from_module, to_module, is_test, include)."""
    for path in files:
        if not path.endswith(SOURCE_SUFFIXES):
            continue
        source_module = module_of(path, modules)
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as handle:
            for number, line in enumerate(handle, 1):
                match = INCLUDE.match(line)
                if not match:
                    continue
                include = match.group(1)
                yield (path, number, source_module, include_module(include, modules),
                       is_test_path(path), include)


CMAKE_CALL = re.compile(r"\b(add_library|add_executable|evloc_add_test|evloc_add_fuzzer|"
                        r"evloc_add_benchmark|evloc_add_proto_library|target_link_libraries)"
                        r"\s*\(", re.MULTILINE)
KEYWORDS = {"PUBLIC", "PRIVATE", "INTERFACE", "STATIC", "SHARED", "OBJECT", "NAME", "SOURCES",
            "LIBS", "LABELS", "PROTOS", "GRPC"}


def call_arguments(text, start):
    """The argument text of the call whose '(' is at text[start - 1]; nested parentheses kept."""
    depth = 1
    index = start
    while index < len(text) and depth:
        if text[index] == "(":
            depth += 1
        elif text[index] == ")":
            depth -= 1
        index += 1
    return text[start:index - 1]


def strip_comments(text):
    return "\n".join(line.split("#", 1)[0] if not line.lstrip().startswith("#") else ""
                     for line in text.splitlines())


def scan_cmake(root, files, modules):
    """Returns (targets, links): targets maps a name to (module, is_test); links is a list of
    (file, line, target, library)."""
    targets = {}
    links = []
    for path in files:
        name = os.path.basename(path)
        if name not in CMAKE_NAMES and not name.endswith(CMAKE_SUFFIXES):
            continue
        folder = os.path.dirname(path)
        folder_module = module_of(folder, modules) if folder else None
        with open(os.path.join(root, path), encoding="utf-8") as handle:
            text = strip_comments(handle.read())
        for match in CMAKE_CALL.finditer(text):
            command = match.group(1)
            arguments = call_arguments(text, match.end())
            line = text.count("\n", 0, match.start()) + 1
            tokens = arguments.split()
            if not tokens:
                continue
            if command in ("add_library", "add_executable"):
                target = tokens[0]
                is_test = target.endswith("_testing") or target.endswith("_seeds")
                targets[target] = (folder_module, is_test)
            elif command == "target_link_libraries":
                for library in tokens[1:]:
                    if library not in KEYWORDS:
                        links.append((path, line, tokens[0], library))
            else:
                target = tokens[tokens.index("NAME") + 1] if "NAME" in tokens else tokens[0]
                targets[target] = (folder_module, command in ("evloc_add_test", "evloc_add_fuzzer"))
                if "LIBS" in tokens:
                    for library in tokens[tokens.index("LIBS") + 1:]:
                        if library in KEYWORDS:
                            break
                        links.append((path, line, target, library))
    return targets, links


def check(root, extra_includes=(), extra_links=()):
    uses, test_uses = read_table(root)
    cycle = find_cycle(uses)
    if cycle:
        raise TableError(f"docs/architecture.md: the layering table has a cycle through {cycle}")
    modules = list(uses)
    allowed = {module: closure(uses, [module]) for module in modules}
    allowed_in_tests = {module: closure(uses, [module] + test_uses[module]) for module in modules}
    files = list_files(root)
    violations = []

    def judge(where, source, target, is_test, what):
        if source is None:
            violations.append(f"{where}: {what}: the file is in no module of the layering table")
            return
        if target is None or target == source:
            return
        table = allowed_in_tests if is_test else allowed
        if target not in table[source]:
            kind = "test code in " if is_test else ""
            may = ", ".join(sorted(table[source] - {source})) or "nothing"
            violations.append(f"{where}: {kind}{source} -> {target} ({what}); {source} may use: "
                              f"{may}")

    for path, line, source, target, is_test, include in list(
            scan_includes(root, files, modules)) + list(extra_includes):
        judge(f"{path}:{line}", source, target, is_test, f'#include "{include}"')
    targets, links = scan_cmake(root, files, modules)
    for path, line, target, library in list(links) + list(extra_links):
        if library not in targets or target not in targets:
            continue
        source, is_test = targets[target]
        judge(f"{path}:{line}", source, targets[library][0], is_test,
              f"{target} links {library}")
    return violations


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", default=os.path.join(os.path.dirname(__file__), ".."))
    parser.add_argument("--self-test", action="store_true")
    options = parser.parse_args()
    root = os.path.abspath(options.root)
    try:
        if options.self_test:
            include = ("maps/map.cc", 1, "maps", "localizer/service", False,
                       "localizer/service/session.h")
            link = ("maps/CMakeLists.txt", 1, "evloc_maps", "evloc_service")
            violations = check(root, [include], [link])
            found_include = any("maps -> localizer/service (#include" in v for v in violations)
            found_link = any("evloc_maps links evloc_service" in v for v in violations)
            print(f"check_layering self-test: injected include "
                  f"{'reported' if found_include else 'MISSED'}, injected link "
                  f"{'reported' if found_link else 'MISSED'}")
            return 0 if found_include and found_link else 1
        violations = check(root)
    except TableError as error:
        print(f"check_layering: error: {error}", file=sys.stderr)
        return 2
    for violation in violations:
        print(violation)
    if violations:
        print(f"check_layering: {len(violations)} edge(s) break the layering table of "
              f"docs/architecture.md", file=sys.stderr)
        return 1
    print("check_layering: every #include and link follows docs/architecture.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
