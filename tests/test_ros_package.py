"""The simlan_msgs ROS 2 interface package (issue 22): ``colcon build`` of the shipped package is
the only step before ``ros2 bag play`` can publish a recording (docs/ros2.md).

Checked with ROS 2's own tools where Debian packages them (Debian 12 ships rosidl 3.3, colcon and
ament-cmake, but neither ROS 2's std_msgs/geometry_msgs nor rosidl_default_generators):

- every .msg parses with rosidl's parser (``rosidl_adapter``, in the system Python) and equals, field
  by field, the definition a recording embeds in its MCAP schemas;
- package.xml is valid for catkin_pkg (REP 149, format 3) and depends on every package a .msg uses;
  CMakeLists.txt lists every .msg file;
- slow: ``colcon build`` with Debian's rosidl C/C++ generators, the dependencies made from the
  definitions the bag embeds.

The ROS tools live in the system Python (/usr/bin/python3), not in the test venv: the tests run
them in subprocesses and skip, naming the apt command, where they are missing.
"""

from __future__ import annotations

import functools
import json
import keyword
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg

import simlan_data
from simlan_data.constants import MSG_DIR
from simlan_data.recording.schema import Topic, typestore
from simlan_data.recording.writer import RecordingWriter

PKG = "simlan_msgs"
PKG_DIR = MSG_DIR / PKG
SYSTEM_PYTHON = "/usr/bin/python3"  # where Debian's python3-rosidl and python3-catkin-pkg live
APT_CHECK = "apt-get install python3-rosidl python3-catkin-pkg"
APT_BUILD = "apt-get install colcon python3-colcon-ros python3-colcon-cmake ament-cmake rosidl-core"
# the separator between a definition and each type it uses, in a ros2msg schema (as in rosbag2)
_DEPENDENCY = re.compile(r"^={80}\nMSG: (\S+)\n", re.MULTILINE)

# rosidl_generator_cpp writes field names verbatim as C++ members (ros2/rosidl#272, still so in
# Jazzy's msg__struct.hpp.em): a field named after a C++ keyword fails every ROS 2 build.
# cppreference's keyword list (C++23, with the alternative tokens).
CPP_KEYWORDS = frozenset(
    """alignas alignof and and_eq asm atomic_cancel atomic_commit atomic_noexcept auto
    bitand bitor bool break case catch char char8_t char16_t char32_t class compl concept
    const consteval constexpr constinit const_cast continue co_await co_return co_yield
    decltype default delete do double dynamic_cast else enum explicit export extern false
    float for friend goto if inline int long mutable namespace new noexcept not not_eq
    nullptr operator or or_eq private protected public reflexpr register reinterpret_cast
    requires return short signed sizeof static static_assert static_cast struct switch
    synchronized template this thread_local throw true try typedef typeid typename union
    unsigned using virtual void volatile wchar_t while xor xor_eq""".split()  # noqa: SIM905 (a word list reads better as text)
)


# ------------------------------------------------------------------------------ ROS tools
@functools.cache
def _system_python_has(module: str) -> bool:
    if not Path(SYSTEM_PYTHON).is_file():
        return False
    proc = subprocess.run([SYSTEM_PYTHON, "-c", f"import {module}"], capture_output=True, timeout=60)
    return proc.returncode == 0


def _require_system_module(module: str, apt: str) -> None:
    if not _system_python_has(module):
        pytest.skip(f"ROS 2 tool {module} not installed in {SYSTEM_PYTHON}: {apt} (docs/ros2.md)")


# Runs in the system Python: {key: [package, type, text]} on stdin -> {key: parsed} on stdout.
_ROSIDL_PARSE = """
import json, sys
from rosidl_adapter.parser import parse_message_string
out = {}
for key, (pkg, name, text) in json.load(sys.stdin).items():
    try:
        spec = parse_message_string(pkg, name, text)
    except Exception as err:
        out[key] = {"error": f"{type(err).__name__}: {err}"}
        continue
    out[key] = {
        "fields": [
            {"name": f.name, "package": f.type.pkg_name, "type": f.type.type,
             "is_array": f.type.is_array, "array_size": f.type.array_size,
             "is_upper_bound": f.type.is_upper_bound,
             "string_upper_bound": f.type.string_upper_bound, "default": repr(f.default_value)}
            for f in spec.fields
        ],
        "constants": [{"name": c.name, "type": c.type, "value": repr(c.value)} for c in spec.constants],
    }
json.dump(out, sys.stdout)
"""


def _rosidl_parse(definitions: dict[str, tuple[str, str, str]]) -> dict[str, dict[str, Any]]:
    """Parse {key: (package, type, .msg text)} with rosidl's own parser (one subprocess)."""
    proc = subprocess.run(
        [SYSTEM_PYTHON, "-c", _ROSIDL_PARSE],
        input=json.dumps(definitions),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


# ------------------------------------------------------------------------------ definitions
def _shipped_texts() -> dict[str, str]:
    """{type name: .msg text} of the package's msg/ folder."""
    return {p.stem: p.read_text() for p in sorted((PKG_DIR / "msg").glob("*.msg"))}


def _embedded(bag: Path) -> dict[str, str]:
    """{type name: full ros2msg definition} of every simlan_msgs schema in an MCAP file."""
    with bag.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    out = {}
    for schema in summary.schemas.values():
        if schema.name.startswith(f"{PKG}/msg/"):
            assert schema.encoding == "ros2msg", schema.name
            out[schema.name.rsplit("/", 1)[1]] = schema.data.decode()
    return out


def _split(definition: str) -> tuple[str, dict[str, str]]:
    """A ros2msg schema -> (its own definition, {package/Type: definition} of the types it uses)."""
    parts = _DEPENDENCY.split(definition)
    return parts[0], dict(zip(parts[1::2], parts[2::2], strict=True))


def _differences(shipped: dict[str, str], embedded: dict[str, str]) -> list[str]:
    """What rosidl parses differently in the shipped .msg files and a bag's embedded definitions.

    One line per differing type: a type embedded without a .msg, a parse error, or the fields and
    constants (name, type, package, array-ness, bounds, default) of both sides.
    """
    queries = {f"msg:{name}": (PKG, name, text) for name, text in shipped.items()}
    queries |= {f"bag:{name}": (PKG, name, _split(text)[0]) for name, text in embedded.items()}
    parsed = _rosidl_parse(queries)
    out = []
    for name in sorted(embedded):
        if name not in shipped:
            out.append(f"{name}: embedded in the bag, no msg/{name}.msg")
            continue
        ours, theirs = parsed[f"msg:{name}"], parsed[f"bag:{name}"]
        if ours != theirs:
            out.append(f"{name}: .msg {ours} != bag {theirs}")
    return out


def _used_packages(texts: dict[str, str]) -> set[str]:
    """Packages (other than simlan_msgs) whose types the .msg files use, parsed by rosbags."""

    def package_of(kind: Nodetype, detail: Any) -> str | None:
        if kind == Nodetype.NAME:
            return str(detail).split("/", 1)[0]
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return package_of(*detail[0])
        return None

    used: set[str] = set()
    for name, text in texts.items():
        for _, fields in get_types_from_msg(text, f"{PKG}/msg/{name}").values():
            used |= {p for _, (kind, detail) in fields if (p := package_of(kind, detail))}
    return used - {PKG}


# ------------------------------------------------------------------------------ bags
def _zero_message(msgtype: str) -> Any:
    """A message of ``msgtype`` with every field zero or empty (built from the typestore)."""
    store = typestore()

    def zero(kind: Nodetype, detail: Any) -> Any:
        if kind == Nodetype.NAME:
            return _zero_message(detail)
        if kind == Nodetype.BASE:
            return {"string": "", "bool": False}.get(detail[0], 0)
        (sub_kind, sub_detail), size = detail
        if sub_kind == Nodetype.BASE and sub_detail[0] not in ("string", "bool"):
            return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=sub_detail[0])
        return [zero(sub_kind, sub_detail) for _ in range(size if kind == Nodetype.ARRAY else 0)]

    _, fields = store.fielddefs[msgtype]
    return store.types[msgtype](**{name: zero(kind, detail) for name, (kind, detail) in fields})


@pytest.fixture(scope="module")
def all_types_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bag written by the recorder's writer with one message of every simlan_msgs type (a run
    publishes SafetyEvent and PoseLandmarks only in some scenarios)."""
    bag = tmp_path_factory.mktemp("ros_package") / "bag"
    with RecordingWriter(bag) as writer:
        for name in _shipped_texts():
            msgtype = f"{PKG}/msg/{name}"
            writer.write(Topic(f"/check/{name}", msgtype, ""), 0, _zero_message(msgtype))
    return bag / "bag.mcap"


# ------------------------------------------------------------------------------ tests: rosidl
def test_every_msg_parses_with_rosidl_as_the_recordings_embed_it(
    short_run: Path, all_types_bag: Path
) -> None:
    _require_system_module("rosidl_adapter", APT_CHECK)
    shipped = _shipped_texts()
    assert (
        len(shipped) == 14
    )  # (issue 25 added InstanceTable, InstanceBoxes2D, InstanceBoxes3D, InstanceKeypoints)
    covered: set[str] = set()
    for bag in (short_run / "recording" / "recording.mcap", all_types_bag):
        embedded = _embedded(bag)
        assert _differences(shipped, embedded) == [], bag
        covered |= set(embedded)
    assert covered == set(shipped)
    # rosidl parses the definitions of the types they use (std_msgs, geometry_msgs, ...) too, and
    # every schema carries all of them: a reader needs nothing but the bag
    dependencies = {
        dep: text for d in _embedded(all_types_bag).values() for dep, text in _split(d)[1].items()
    }
    queries = {
        dep: (dep.partition("/")[0], dep.partition("/")[2], text) for dep, text in dependencies.items()
    }
    parsed = _rosidl_parse(queries)
    assert not [p for p in parsed.values() if "error" in p]
    used = {f"{f['package']}/{f['type']}" for p in parsed.values() for f in p["fields"] if f["package"]}
    assert used <= set(dependencies)
    assert {dep.split("/")[0] for dep in dependencies} >= _used_packages(shipped)


def test_a_msg_that_differs_from_the_bag_is_reported(all_types_bag: Path) -> None:
    """The comparison above can fail: each kind of change to a .msg is found."""
    _require_system_module("rosidl_adapter", APT_CHECK)
    shipped = _shipped_texts()
    changed = dict(shipped)
    edits = {
        "LocalizationStatus": ("float64 fix_age_s", "float32 fix_age_s"),  # type
        "NavigationStatus": ("uint32 goal_index", "uint32 goal_idx"),  # name
        "MarkerDetections": ("int32[] ids", "int32[8] ids"),  # array size
        "CollisionState": ("bool in_collision", "bool in_collision false"),  # default
        "SemanticLabels": ("uint8[] ids", "uint8 UNLABELED=0\nuint8[] ids"),  # constant
        "RunInfo": ("string scenario", "string<=64 scenario"),  # bound
    }
    for name, (old, new) in edits.items():
        assert old in changed[name], name
        changed[name] = changed[name].replace(old, new)
    changed["Extra"] = "bool x\n"  # a .msg that no bag embeds is fine; one embedded and missing is not
    del changed["SafetyState"]
    found = _differences(changed, _embedded(all_types_bag))
    assert [line.split(":")[0] for line in found] == sorted([*edits, "SafetyState"])
    assert any(line.endswith("no msg/SafetyState.msg") for line in found)


@pytest.mark.parametrize(
    "name",
    sorted(_shipped_texts()),
)
def test_no_field_is_a_cpp_or_python_keyword(name: str) -> None:
    """ROS 2's C++ generator uses field names as member names; its Python one as attributes."""
    ((_, fields),) = get_types_from_msg(_shipped_texts()[name], f"{PKG}/msg/{name}").values()
    bad = [f for f, _ in fields if f in CPP_KEYWORDS or keyword.iskeyword(f)]
    assert bad == [], f"{name}.msg: fields named after a C++/Python keyword: {bad}"


# ------------------------------------------------------------------------------ tests: package files
def test_package_xml_declares_an_interface_package_with_every_used_dependency() -> None:
    root = ET.parse(PKG_DIR / "package.xml").getroot()
    assert (root.tag, root.get("format")) == ("package", "3")

    def texts(tag: str) -> list[str]:
        return [(e.text or "").strip() for e in root.findall(tag)]

    assert texts("name") == [PKG] == [PKG_DIR.name]
    assert texts("version") == [simlan_data.__version__]
    assert texts("license") == ["Apache-2.0"]
    assert root.find("description") is not None and root.find("maintainer") is not None
    assert "@" in (root.find("maintainer").get("email") or "")  # type: ignore[union-attr]
    assert set(texts("buildtool_depend")) == {"ament_cmake", "rosidl_default_generators"}
    assert texts("exec_depend") == ["rosidl_default_runtime"]
    assert texts("member_of_group") == ["rosidl_interface_packages"]
    assert texts("export/build_type") == ["ament_cmake"]
    assert set(texts("depend")) == _used_packages(_shipped_texts())


def test_cmakelists_generates_every_msg_with_its_dependencies() -> None:
    cmake = (PKG_DIR / "CMakeLists.txt").read_text()
    assert re.search(r"^project\(simlan_msgs\)$", cmake, re.MULTILINE)
    call = re.search(r"rosidl_generate_interfaces\(\$\{PROJECT_NAME\}(.*?)\)", cmake, re.DOTALL)
    assert call is not None
    files, _, deps = call.group(1).partition("DEPENDENCIES")
    assert re.findall(r'"msg/(\w+)\.msg"', files) == sorted(_shipped_texts())
    used = _used_packages(_shipped_texts())
    assert set(deps.split()) == used
    found = set(re.findall(r"^find_package\((\w+) REQUIRED\)$", cmake, re.MULTILINE))
    assert found == {"ament_cmake", "rosidl_default_generators", *used}


def test_package_xml_is_valid_for_catkin_pkg() -> None:
    """REP 149 as ROS tools read it (catkin_pkg's parser and validator, no warnings)."""
    _require_system_module("catkin_pkg", APT_CHECK)
    script = (
        "import json, sys\n"
        "from catkin_pkg.package import parse_package\n"
        "warnings = []\n"
        "p = parse_package(sys.argv[1], warnings=warnings)\n"
        "p.validate(warnings=warnings)\n"
        "print(json.dumps([p.name, p.get_build_type(), [g.name for g in p.member_of_groups], warnings]))\n"
    )
    proc = subprocess.run(
        [SYSTEM_PYTHON, "-c", script, str(PKG_DIR)], capture_output=True, text=True, timeout=60, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == [PKG, "ament_cmake", ["rosidl_interface_packages"], []]


# ------------------------------------------------------------------------------ slow: colcon build
_GENERATORS_PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>rosidl_default_generators</name><version>0.0.0</version>
  <description>Debian's rosidl generators under ROS 2's meta-package name (test workspace)</description>
  <maintainer email="tests@example.org">tests</maintainer><license>Apache-2.0</license>
  <buildtool_depend>ament_cmake_core</buildtool_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
_GENERATORS_CMAKE = """cmake_minimum_required(VERSION 3.8)
project(rosidl_default_generators NONE)
find_package(ament_cmake_core REQUIRED)
ament_package(CONFIG_EXTRAS extras.cmake)
"""
# what Jazzy's rosidl_default_generators finds, less the generators Debian does not package
# (rosidl_generator_py, rosidl_typesupport_c/cpp, the DDS type supports)
_GENERATORS_EXTRAS = "".join(
    f"find_package({p} REQUIRED)\n"
    for p in (
        "rosidl_cmake",
        "rosidl_generator_c",
        "rosidl_generator_cpp",
        "rosidl_typesupport_introspection_c",
        "rosidl_typesupport_introspection_cpp",
    )
)


def _interface_package(root: Path, pkg: str, types: dict[str, str]) -> None:
    """Write an interface package like simlan_msgs for ``types`` ({Type: .msg text})."""
    (root / "msg").mkdir(parents=True)
    for name, text in types.items():
        (root / "msg" / f"{name}.msg").write_text(text)
    used = sorted(
        {t.split("/")[0] for t in re.findall(r"^(\w+/\w+) ", "".join(types.values()), re.M)} - {pkg}
    )
    depends = "".join(f"<depend>{u}</depend>" for u in used)
    (root / "package.xml").write_text(
        f'<?xml version="1.0"?>\n<package format="3"><name>{pkg}</name><version>0.0.0</version>'
        f"<description>from a recording's embedded definitions</description>"
        f'<maintainer email="tests@example.org">tests</maintainer><license>Apache-2.0</license>'
        f"<buildtool_depend>ament_cmake</buildtool_depend>"
        f"<buildtool_depend>rosidl_default_generators</buildtool_depend>{depends}"
        f"<member_of_group>rosidl_interface_packages</member_of_group>"
        f"<export><build_type>ament_cmake</build_type></export></package>\n"
    )
    files = " ".join(f'"msg/{name}.msg"' for name in types)
    dependencies = f" DEPENDENCIES {' '.join(used)}" if used else ""
    (root / "CMakeLists.txt").write_text(
        f"cmake_minimum_required(VERSION 3.8)\nproject({pkg})\n"
        "find_package(ament_cmake REQUIRED)\nfind_package(rosidl_default_generators REQUIRED)\n"
        + "".join(f"find_package({u} REQUIRED)\n" for u in used)
        + f"rosidl_generate_interfaces(${{PROJECT_NAME}} {files}{dependencies})\nament_package()\n"
    )


def _workspace(src: Path, bag: Path) -> None:
    """simlan_msgs as shipped, plus what Debian lacks: the types it uses, made from the
    definitions the bag embeds (Jazzy's), and rosidl_default_generators over Debian's generators."""
    shutil.copytree(PKG_DIR, src / PKG)
    generators = src / "rosidl_default_generators"
    generators.mkdir(parents=True)
    (generators / "package.xml").write_text(_GENERATORS_PACKAGE_XML)
    (generators / "CMakeLists.txt").write_text(_GENERATORS_CMAKE)
    (generators / "extras.cmake").write_text(_GENERATORS_EXTRAS)
    underlay: dict[str, dict[str, str]] = {}
    for definition in _embedded(bag).values():
        for dep, text in _split(definition)[1].items():
            pkg, name = dep.split("/")
            underlay.setdefault(pkg, {})[name] = text
    for pkg, types in underlay.items():
        _interface_package(src / pkg, pkg, types)


@pytest.mark.slow
def test_colcon_builds_the_package_with_debians_rosidl_generators(
    tmp_path: Path, all_types_bag: Path
) -> None:
    """About 30 s on 2 cores: rosidl's C and C++ generators and introspection type supports."""
    if (
        shutil.which("colcon", path="/usr/bin") is None
        or not Path("/usr/share/rosidl_generator_cpp").is_dir()
    ):
        pytest.skip(f"colcon or rosidl's generators not installed: {APT_BUILD} (docs/ros2.md)")
    _workspace(tmp_path / "src", all_types_bag)
    # ament's CMake runs `python3` and needs the system one (ament_package, rosidl), not the venv's
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "LANG": os.environ.get("LANG", "C.UTF-8")}
    proc = subprocess.run(
        ["colcon", "build", "--event-handlers", "console_cohesion+"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-3000:]
    index = (
        tmp_path / "install" / PKG / "share" / "ament_index" / "resource_index" / "rosidl_interfaces" / PKG
    )
    listed = {Path(line).stem for line in index.read_text().split()}
    assert listed == set(_shipped_texts())
    lib = tmp_path / "install" / PKG / "lib"
    for part in (
        "rosidl_generator_c",
        "rosidl_typesupport_introspection_c",
        "rosidl_typesupport_introspection_cpp",
    ):
        assert (lib / f"lib{PKG}__{part}.so").is_file(), part
