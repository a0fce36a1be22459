"""URDF helpers: resolve robot URIs and produce a self-contained robot description.

ROS-free except for the optional ``rospkg`` lookup of ``package://`` URIs.
"""

import copy
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported where it is used: robot_description runs under a python without it
    import numpy as np

__all__ = [
    "UrdfError",
    "JointLimits",
    "chain_reach",
    "CONTINUOUS_JOINT_LIMIT",
    "resolve_uri",
    "rewrite_mesh_paths",
    "robot_description",
]

#: Position limits (rad) given to continuous joints, as the planning scene's RobotModel::kContinuousJointLimit does.
CONTINUOUS_JOINT_LIMIT = 2.0 * math.pi


class UrdfError(Exception):
    """A URDF (or one of its meshes) cannot be found or is not valid."""


def _ros_package_path(pkg):
    """Absolute path of a ROS package, or None when rospkg is missing or does not know it."""
    try:
        import rospkg
    except ImportError:
        return None
    try:
        return rospkg.RosPack().get_path(pkg)
    except Exception:  # rospkg.ResourceNotFound, bad ROS_PACKAGE_PATH, ...
        return None


def _pybullet_data_path():
    try:
        import pybullet_data
    except ImportError as exc:
        raise UrdfError("pybullet_data:// URI but the pybullet_data package is not installed") from exc
    return pybullet_data.getDataPath()


def resolve_uri(uri, base_dir=None):
    """Turn a URI into an absolute file path (the file is not required to exist).

    Accepted: an absolute path, ``file:///abs/path``, ``package://<ros_pkg>/<rel>`` (rospkg; when no
    ROS package has that name, ``<base_dir>/<ros_pkg>/<rel>`` is used, the habit of URDFs that say
    ``package://meshes/...`` relative to their own folder), ``pybullet_data://<rel>`` and a relative
    path (relative to ``base_dir``, or the current directory).
    """
    if not isinstance(uri, str) or not uri.strip():
        raise UrdfError("empty URI")
    uri = uri.strip()
    if uri.startswith("file://"):
        path = uri[len("file://") :]
        if not os.path.isabs(path):
            raise UrdfError("file:// URI must hold an absolute path: %r" % uri)
        return os.path.normpath(path)
    if uri.startswith("pybullet_data://"):
        rel = uri[len("pybullet_data://") :].lstrip("/")
        return os.path.normpath(os.path.join(_pybullet_data_path(), rel))
    if uri.startswith("package://"):
        rest = uri[len("package://") :]
        pkg, _, rel = rest.partition("/")
        if not pkg or not rel:
            raise UrdfError("malformed package:// URI (expected package://<pkg>/<path>): %r" % uri)
        pkg_path = _ros_package_path(pkg)
        if pkg_path is not None:
            return os.path.normpath(os.path.join(pkg_path, rel))
        if base_dir is not None:
            return os.path.normpath(os.path.join(base_dir, pkg, rel))
        raise UrdfError("no ROS package named %r (from %r) and no base folder to resolve it in" % (pkg, uri))
    if "://" in uri:
        raise UrdfError("unsupported URI scheme: %r (use a path, file://, package:// or pybullet_data://)" % uri)
    if os.path.isabs(uri):
        return os.path.normpath(uri)
    return os.path.normpath(os.path.join(base_dir if base_dir is not None else os.getcwd(), uri))


@dataclass(frozen=True)
class JointLimits:
    """Position and velocity limits of the controlled joints, in their configured order: THE Python reading of a
    URDF's <limit> elements (the simulator, the env and its action scaling use it; C++ reads them once too, in the
    planning scene's RobotModel). Continuous joints get +-CONTINUOUS_JOINT_LIMIT."""

    names: tuple
    lower: "np.ndarray"
    upper: "np.ndarray"
    velocity: "np.ndarray"

    @classmethod
    def from_urdf(cls, urdf_xml: str, joints) -> "JointLimits":
        """Read the limits of `joints` from URDF text.

        Raises:
            ValueError: the URDF does not parse, a joint is missing, not revolute, prismatic or continuous, or has no
                usable <limit> (finite lower < upper for revolute and prismatic joints, velocity > 0).
        """
        import numpy as np  # here: robot_description runs this module under a python without numpy

        try:
            root = ET.fromstring(urdf_xml)
        except ET.ParseError as exc:
            raise ValueError(f"the robot description is not valid XML: {exc}") from exc
        # Only the <robot>'s own joints: a <transmission> also holds <joint name=...> elements (ros_control).
        by_name = {j.get("name"): j for j in root.findall("joint")}
        lower, upper, velocity = [], [], []
        for name in joints:
            joint = by_name.get(name)
            if joint is None:
                raise ValueError(f"joint '{name}' is not in the URDF (it has: {sorted(n for n in by_name if n)})")
            kind, limit = joint.get("type"), joint.find("limit")
            if kind not in ("revolute", "prismatic", "continuous") or limit is None:
                raise ValueError(f"joint '{name}' must be revolute, prismatic or continuous with a <limit>")
            vel = float(limit.get("velocity", "nan"))
            if kind == "continuous":
                lo, hi = -CONTINUOUS_JOINT_LIMIT, CONTINUOUS_JOINT_LIMIT
            else:
                lo, hi = (float(limit.get(k, "nan")) for k in ("lower", "upper"))
            if not (np.isfinite([lo, hi, vel]).all() and lo < hi and vel > 0):
                raise ValueError(f"joint '{name}' has unusable limits lower={lo} upper={hi} velocity={vel}")
            lower.append(lo)
            upper.append(hi)
            velocity.append(vel)
        return cls(tuple(joints), np.array(lower), np.array(upper), np.array(velocity))

    @property
    def size(self) -> int:
        return len(self.names)


def chain_reach(urdf_xml: str, tip_link: str) -> float:
    """An upper bound (m) of how far the origin of `tip_link` can get from the origin of any of its ancestor links (the
    robot's base among them), in any configuration: the lengths of the joint origins' offsets on the chain from the URDF
    root to the tip, summed (triangle inequality), plus the largest travel of every prismatic joint on it.

    The env bounds its observation space with it (end-effector and goal positions within +-reach of the base).

    Raises:
        ValueError: the URDF does not parse, or it has no link `tip_link`.
    """
    try:
        root = ET.fromstring(urdf_xml)
    except ET.ParseError as exc:
        raise ValueError(f"the robot description is not valid XML: {exc}") from exc
    if tip_link not in {link.get("name") for link in root.findall("link")}:
        raise ValueError(f"link '{tip_link}' is not in the URDF")
    parent_joint = {}
    for joint in root.findall("joint"):  # not the <joint> elements inside <transmission>s
        child = joint.find("child")
        if child is not None:
            parent_joint[child.get("link")] = joint
    reach, link, seen = 0.0, tip_link, set()
    while link in parent_joint and link not in seen:
        seen.add(link)
        joint = parent_joint[link]
        origin = joint.find("origin")
        xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
        reach += math.sqrt(sum(v * v for v in xyz))
        limit = joint.find("limit")
        if joint.get("type") == "prismatic" and limit is not None:
            reach += max(abs(float(limit.get("lower", "0"))), abs(float(limit.get("upper", "0"))))
        link = joint.find("parent").get("link")
    return reach


def _parse_urdf(text, source):
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError("%s is not valid XML: %s" % (source, exc)) from None
    if root.tag != "robot":
        raise UrdfError("%s is not a URDF: root element is <%s>, expected <robot>" % (source, root.tag))
    if root.find("link") is None:
        raise UrdfError("%s is not a URDF: it has no <link>" % source)
    return root


def rewrite_mesh_paths(text, base_dir=None, source="robot description", check_exists=True):
    """Return URDF text where every ``<mesh filename=...>`` is an absolute path.

    Raises UrdfError when the text is not a URDF or (check_exists) a mesh file does not exist.
    """
    root = _parse_urdf(text, source)
    for mesh in root.iter("mesh"):
        fname = mesh.get("filename")
        if fname is None:
            raise UrdfError("%s: a <mesh> element has no filename attribute" % source)
        path = resolve_uri(fname, base_dir)
        if check_exists and not os.path.isfile(path):
            raise UrdfError("%s: mesh %r resolves to %s, which does not exist" % (source, fname, path))
        mesh.set("filename", path)
    return '<?xml version="1.0" ?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def collision_as_visual(text, base_dir=None, source="robot description"):
    """URDF text whose links look like their collision shapes: each link's <visual> elements are replaced by its
    <collision> elements' origins and geometries (no material), so that a renderer draws the collision shapes (the
    simulator's depth cameras: a link's convex hull has a few hundred triangles where its visual mesh may have tens of
    thousands). A link without a <collision> keeps its visuals (a camera must not see through it). Mesh paths come out
    absolute (rewrite_mesh_paths), so the text can be written anywhere."""
    root = _parse_urdf(rewrite_mesh_paths(text, base_dir, source), source)
    for link in root.findall("link"):
        collisions = link.findall("collision")
        if not collisions:
            continue
        for visual in link.findall("visual"):
            link.remove(visual)
        for collision in collisions:
            visual = ET.SubElement(link, "visual")
            for tag in ("origin", "geometry"):
                element = collision.find(tag)
                if element is not None:
                    visual.append(copy.deepcopy(element))
    return '<?xml version="1.0" ?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def simplified_visuals(text, out_dir, max_faces, base_dir=None, source="robot description"):
    """URDF text whose visual meshes (OBJ, STL, COLLADA) are drawn simplified: each is read, decimated to at most
    about max_faces triangles (moverl_sim.meshes) and written to ``out_dir`` as an OBJ the text names (absolute paths),
    so that a renderer draws a fraction of the triangles with the same silhouette to within millimetres (the
    simulator's depth cameras; render_cost.py measures it). Collision shapes, primitives and meshes of other formats
    stay as they are, and so does a COLLADA file moverl_sim.meshes cannot read (PyBullet reads COLLADA with its own
    reader; the depth cameras' rasterizer then says why TinyRenderer draws them). A mesh of another kind that cannot be
    read is refused. ``out_dir`` must exist and outlive the loading of the text."""
    from . import meshes

    root = _parse_urdf(rewrite_mesh_paths(text, base_dir, source), source)
    written = {}
    for visual in root.iter("visual"):
        for mesh in visual.iter("mesh"):
            path = mesh.get("filename")
            if os.path.splitext(path)[1].lower() not in meshes.SIMPLIFIABLE:
                continue
            if path not in written:
                try:
                    vertices, faces = meshes.read_mesh(path)
                    small = len(faces) <= max_faces  # drawn as it is
                    if not small:
                        vertices, faces = meshes.simplified(vertices, faces, max_faces)
                except (OSError, ValueError) as exc:
                    if not (path.lower().endswith(".dae") and isinstance(exc, ValueError)):
                        raise UrdfError("%s: visual mesh %s cannot be simplified: %s" % (source, path, exc)) from None
                    small = True  # a COLLADA file PyBullet's own reader draws
                if small:
                    written[path] = path
                else:
                    written[path] = os.path.join(out_dir, "%d_%s.obj" % (len(written), os.path.basename(path)))
                    meshes.write_obj(written[path], vertices, faces)
            mesh.set("filename", written[path])
    return '<?xml version="1.0" ?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def robot_description(uri):
    """The URDF text of ``uri`` with every mesh filename rewritten to an absolute, existing path."""
    path = resolve_uri(uri)
    if not os.path.isfile(path):
        raise UrdfError("URDF file not found: %s (from %r)" % (path, uri))
    try:
        with open(path, "r", encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise UrdfError("cannot read URDF %s: %s" % (path, exc)) from None
    return rewrite_mesh_paths(text, base_dir=os.path.dirname(path), source=path)
