"""A serial arm loaded from URDF into Pinocchio: limits, forward kinematics, Jacobian.

A :class:`Robot` is the chain from the URDF's root link to one tip frame. Joints that are not
on that chain (grippers, fingers) are locked, so ``q`` holds exactly one value per chain joint,
in chain order: angles [rad] for revolute and continuous joints, displacements [m] for
prismatic ones. Poses are expressed in the URDF root frame (the "base frame").
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import numpy as np
import pinocchio as pin

from planner.core.arrays import read_only
from planner.core.files import read_text_file
from planner.exceptions import (
    InvalidArgumentError,
    InvalidConfigurationError,
    InvalidLimitsError,
    JointLimitError,
    UnknownFrameError,
    URDFError,
)
from planner.model.derived import DerivedCache

__all__ = ["Robot", "Task"]

Task = Literal["position", "pose"]

_REVOLUTE = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")
_CONTINUOUS = ("JointModelRUBX", "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned")
_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")


def _validate_urdf(text: str, source: str) -> None:
    """Check URDF text with lxml and yourdfpy; raise URDFError saying what is wrong."""
    import yourdfpy
    from lxml import etree

    try:
        root = etree.fromstring(text.encode())
    except etree.XMLSyntaxError as exc:
        raise URDFError(f"{source}: malformed XML: {exc}") from exc
    if root.tag != "robot":
        raise URDFError(f"{source}: the root element is <{root.tag}>, a URDF's must be <robot>")
    links = [el.get("name") for el in root.findall("link")]
    if None in links:
        raise URDFError(f"{source}: a <link> has no name attribute")
    duplicates = sorted({n for n in links if links.count(n) > 1})
    if duplicates:
        raise URDFError(f"{source}: link names repeated: {', '.join(duplicates)}")
    for joint in root.findall("joint"):
        jname = joint.get("name")
        if jname is None:
            raise URDFError(f"{source}: a <joint> has no name attribute")
        for tag in ("parent", "child"):
            el = joint.find(tag)
            if el is None or el.get("link") is None:
                raise URDFError(f"{source}: joint {jname!r} has no <{tag} link=...>")
            if el.get("link") not in links:
                raise URDFError(
                    f"{source}: joint {jname!r} names {tag} link {el.get('link')!r}, "
                    f"which is not defined; links: {', '.join(links)}"
                )
    try:
        urdf = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=False, load_meshes=False)
    except Exception as exc:  # yourdfpy surfaces parse problems as assorted built-in errors
        raise URDFError(f"{source}: yourdfpy cannot parse it: {type(exc).__name__}: {exc}") from exc
    if not urdf.validate():
        raise URDFError(f"{source}: invalid URDF: {'; '.join(str(e) for e in urdf.errors)}")
    for jname, joint in urdf.joint_map.items():
        if joint.type in ("revolute", "prismatic") and joint.limit is None:
            raise URDFError(f"{source}: {joint.type} joint {jname!r} has no <limit>")
        lim = joint.limit
        if lim is None or joint.type == "fixed":
            continue
        for attr in ("lower", "upper", "velocity", "effort"):
            v = getattr(lim, attr)
            if v is not None and math.isnan(v):
                raise InvalidLimitsError(f"{source}: joint {jname!r} {attr} limit is NaN", joint=jname, value=v)
        if joint.type != "continuous" and lim.lower is not None and lim.upper is not None and lim.lower > lim.upper:
            raise InvalidLimitsError(
                f"{source}: joint {jname!r} has lower limit {lim.lower:.6g} > upper limit {lim.upper:.6g}",
                joint=jname,
                value=(lim.lower, lim.upper),
            )
        if lim.velocity is not None and lim.velocity < 0:
            raise InvalidLimitsError(
                f"{source}: joint {jname!r} has a negative velocity limit {lim.velocity:.6g}",
                joint=jname,
                value=lim.velocity,
            )


_FRAME_PREFERENCE = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT)


def _find_frame(model: pin.Model, name: str) -> int | None:
    """Index of the frame called `name`; a link (body) wins over a joint of the same name."""
    matches = [i for i, f in enumerate(model.frames) if f.name == name]
    if not matches:
        return None
    return min(
        matches,
        key=lambda i: (
            _FRAME_PREFERENCE.index(model.frames[i].type)
            if model.frames[i].type in _FRAME_PREFERENCE
            else len(_FRAME_PREFERENCE)
        ),
    )


def _default_tip(model: pin.Model) -> str:
    """The frame at the end of the deepest chain: the leaf body frame with most joints above it."""
    children = {f.parentFrame for f in model.frames}
    best: tuple[int, int] | None = None
    for fid, frame in enumerate(model.frames):
        if frame.type != pin.FrameType.BODY or fid in children:
            continue
        depth = len(model.supports[frame.parentJoint]) - 1
        if best is None or depth > best[0]:
            best = (depth, fid)
    if best is None:
        raise URDFError("the URDF has no link frame to use as tip")
    return model.frames[best[1]].name


def _chain_length(model: pin.Model, tip_frame_id: int) -> float:
    """Sum of the distances between consecutive joint origins, first joint to tip, at q = 0 [m]."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    tip = pin.updateFramePlacement(model, data, tip_frame_id).translation
    points = [data.oMi[j].translation for j in range(1, model.njoints)] + [tip]
    length = float(sum(np.linalg.norm(b - a) for a, b in zip(points[:-1], points[1:])))
    return length if length > 1e-9 else 1.0


def _rebuild_robot(
    urdf: str, tip: str, name: str, source: str, locked: dict[str, float], approach_axis: tuple[float, ...]
) -> Robot:
    """The robot :meth:`Robot.__reduce__` describes (its URDF was validated when first built)."""
    return Robot(urdf, tip=tip, name=name, source=source, locked=locked, approach_axis=approach_axis, validate=False)


class Robot:
    """A serial chain from the URDF root to a tip frame, modelled in Pinocchio.

    Build one with :func:`planner.load_robot` or :meth:`Robot.from_urdf`. Not thread-safe: it
    owns one ``pinocchio.Data`` workspace; give each thread its own ``copy.deepcopy(robot)``.
    Robots pickle (rebuilt from their URDF text), so they can go to worker processes.

    Attributes:
        name: Robot name.
        model: The reduced Pinocchio model (off-chain joints locked).
        tip: Name of the tip frame.
        approach_axis: Unit approach axis of the tip, in tip-frame coordinates, read-only.
        tip_frame_id: Pinocchio frame index of the tip.
        urdf: The URDF text the robot was built from.
        source: Where the URDF came from (its file path, or ``"<urdf>"``), for messages and
            for resolving the meshes it names.
        locked_joints: The joints off the chain and the values [rad or m] they are locked at.
        derived: Objects built from this robot by higher layers (its IK solvers), kept for
            reuse and freed with the robot (:class:`~planner.model.derived.DerivedCache`).
    """

    def __init__(
        self,
        urdf: str,
        *,
        tip: str | None = None,
        name: str | None = None,
        source: str = "<urdf>",
        locked: Mapping[str, float] | None = None,
        approach_axis: Sequence[float] = (0.0, 0.0, 1.0),
        validate: bool = True,
    ) -> None:
        """Build a robot from URDF text.

        Args:
            urdf: URDF XML text.
            tip: Tip frame name; None picks the end of the deepest chain.
            name: Robot name; None uses the URDF's.
            source: Where the text came from, for error messages.
            locked: Values [rad or m] for joints off the base-to-tip chain; unnamed ones are
                locked at 0 (or at their range's nearest end when 0 is outside it).
            approach_axis: The tip frame's approach axis in tip-frame coordinates (the
                direction the gripper points; used by approach-pitch targets).
            validate: Check the URDF with lxml and yourdfpy first (their messages are clearer
                than Pinocchio's). The bundled arms skip it: their files are generated and
                tested, and yourdfpy's import (trimesh) costs about 0.4 s.

        Raises:
            URDFError: If the URDF is malformed or has unsupported joints on the chain.
            InvalidLimitsError: If a joint has lower > upper, a NaN or a negative speed.
            UnknownFrameError: If `tip` is not a frame of the model.
            InvalidArgumentError: If no joint moves the tip frame, or on bad `locked` values.
        """
        if validate:
            _validate_urdf(urdf, source)
        try:
            full = pin.buildModelFromXML(urdf)
        except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
            raise URDFError(f"{source}: Pinocchio cannot build a model: {exc}") from exc
        self.urdf = urdf
        self.name = name or full.name
        self.source = source
        if tip is None:
            tip = _default_tip(full)
        tip_full = _find_frame(full, tip)
        if tip_full is None:
            raise UnknownFrameError(tip, [f.name for f in full.frames if f.name != "universe"])
        chain = set(full.supports[full.frames[tip_full].parentJoint])
        if chain <= {0}:  # no joint moves the tip: nothing to plan (Ruckig fails on zero joints)
            moved = [f.name for f in full.frames if f.parentJoint > 0 and f.name != "universe"]
            raise InvalidArgumentError(
                f"no joint moves the tip frame {tip!r} (only fixed joints lead to it); frames a joint moves: "
                f"{', '.join(moved) or 'none'}"
            )
        locked = dict(locked or {})
        unknown = sorted(set(locked) - set(full.names[1:]))
        if unknown:
            raise InvalidArgumentError(
                f"cannot lock unknown joints {', '.join(unknown)}; joints: {', '.join(full.names[1:])}"
            )
        q_ref = pin.neutral(full)
        lock_ids = []
        for jid in range(1, full.njoints):
            jname = full.names[jid]
            if jid in chain:
                if jname in locked:
                    raise InvalidArgumentError(f"joint {jname!r} is on the chain to {tip!r}; it cannot be locked")
                continue
            lock_ids.append(jid)
            jm = full.joints[jid]
            if jm.nq == 1:
                lo, hi = full.lowerPositionLimit[jm.idx_q], full.upperPositionLimit[jm.idx_q]
                value = float(locked.get(jname, min(max(0.0, lo), hi)))
                if not lo <= value <= hi:
                    raise JointLimitError(jname, value, lo, hi, context="locked joint")
                q_ref[jm.idx_q] = value
        model = pin.buildReducedModel(full, lock_ids, q_ref) if lock_ids else full
        self.locked_joints: Mapping[str, float] = MappingProxyType(
            {full.names[j]: float(q_ref[full.joints[j].idx_q]) for j in lock_ids if full.joints[j].nq == 1}
        )
        self.model = model
        self.data = model.createData()
        self.tip = tip
        self.tip_frame_id = _find_frame(model, tip)
        axis = np.asarray(approach_axis, dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0.0:
            raise InvalidArgumentError(f"approach_axis must be a non-zero 3-vector, got {approach_axis!r}")
        self.approach_axis = read_only(axis / np.linalg.norm(axis))

        kinds, lower, upper = [], [], []
        for jid in range(1, model.njoints):
            jm = model.joints[jid]
            short = jm.shortname()
            if short in _REVOLUTE:
                kinds.append("revolute")
                lower.append(model.lowerPositionLimit[jm.idx_q])
                upper.append(model.upperPositionLimit[jm.idx_q])
            elif short in _PRISMATIC:
                kinds.append("prismatic")
                lower.append(model.lowerPositionLimit[jm.idx_q])
                upper.append(model.upperPositionLimit[jm.idx_q])
            elif short in _CONTINUOUS:
                kinds.append("continuous")
                lower.append(-math.inf)
                upper.append(math.inf)
            else:
                raise URDFError(
                    f"{source}: joint {model.names[jid]!r} is of type {short}; "
                    "only revolute, continuous and prismatic joints are supported on the chain"
                )
        self.joint_kinds: tuple[str, ...] = tuple(kinds)
        self._lower = read_only(np.array(lower))
        self._upper = read_only(np.array(upper))
        self._velocity = read_only(model.velocityLimit)
        self._has_continuous = "continuous" in kinds
        self._idx_q = [model.joints[j].idx_q for j in range(1, model.njoints)]
        self._characteristic_length = _chain_length(model, self.tip_frame_id)
        # Columns of prismatic joints scaled by that length (see conditioning).
        self._column_scale = read_only(np.where(np.array(kinds) == "prismatic", self._characteristic_length, 1.0))
        self.derived = DerivedCache()

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        tip: str | None = None,
        *,
        name: str | None = None,
        locked: Mapping[str, float] | None = None,
        approach_axis: Sequence[float] = (0.0, 0.0, 1.0),
        validate: bool = True,
    ) -> Robot:
        """Load a robot from a URDF file path or URDF text.

        Args:
            urdf: A path to a ``.urdf`` file, or the XML text itself.
            tip: Tip frame name; None picks the end of the deepest chain.
            name: Robot name; None uses the URDF's.
            locked: Values for joints off the chain (see the constructor).
            approach_axis: The tip's approach axis in tip-frame coordinates.
            validate: Check the URDF with lxml and yourdfpy first (see the constructor).

        Returns:
            The robot.

        Raises:
            URDFError: If the file cannot be read or the URDF is malformed.
        """
        if isinstance(urdf, Path) or (isinstance(urdf, str) and "<" not in urdf):
            path = Path(urdf)
            text = read_text_file(path, "URDF file", URDFError)
            return cls(
                text,
                tip=tip,
                name=name,
                source=str(path),
                locked=locked,
                approach_axis=approach_axis,
                validate=validate,
            )
        return cls(urdf, tip=tip, name=name, locked=locked, approach_axis=approach_axis, validate=validate)

    def __repr__(self) -> str:
        return f"Robot(name={self.name!r}, dof={self.dof}, tip={self.tip!r})"

    def __reduce__(self) -> tuple:
        """Pickling and deep copies rebuild the robot from its URDF text and options.

        So a robot can be sent to worker processes (``multiprocessing``,
        ``concurrent.futures``). The copy has its own ``pinocchio.Data`` and an empty
        :attr:`derived` cache: its IK solvers are built again on first use.
        """
        options = (self.tip, self.name, self.source, dict(self.locked_joints), tuple(self.approach_axis.tolist()))
        return (_rebuild_robot, (self.urdf, *options))

    # ------------------------------------------------------------------ description
    @property
    def dof(self) -> int:
        """Number of chain joints (the length of ``q``)."""
        return self.model.nv

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Chain joint names, base to tip, in the order ``q`` holds them."""
        return tuple(self.model.names[1:])

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits [rad or m], read-only, -inf for continuous joints."""
        return self._lower

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits [rad or m], read-only, +inf for continuous joints."""
        return self._upper

    @property
    def velocity_limit(self) -> np.ndarray:
        """Velocity limits from the URDF [rad/s or m/s], read-only."""
        return self._velocity

    @property
    def characteristic_length(self) -> float:
        """The arm's length [m], which makes the singularity measure independent of its size.

        The sum of the distances between consecutive joint origins from the first joint to the
        tip (the first joint's pedestal excluded), taken at q = 0; for revolute joints it does
        not depend on q. It bounds the tip's distance from the first joint origin, and equals
        it when the arm can stretch out straight. :meth:`conditioning` weighs a tip rotation
        of 1 rad like a tip translation of this length, and a prismatic joint's travel of this
        length like a revolute joint's 1 rad (1 m for a chain of zero length).
        """
        return self._characteristic_length

    @property
    def frame_names(self) -> tuple[str, ...]:
        """Names of all frames of the (reduced) model."""
        return tuple(f.name for f in self.model.frames if f.name != "universe")

    @property
    def base(self) -> str:
        """Name of the root link the poses are expressed in."""
        for f in self.model.frames:
            if f.type == pin.FrameType.BODY and f.parentJoint == 0:
                return f.name
        return "universe"

    def frame_id(self, frame: str | None) -> int:
        """Pinocchio index of a frame; None means the tip.

        Raises:
            UnknownFrameError: If the frame does not exist (the message lists the frames).
        """
        if frame is None:
            return self.tip_frame_id
        fid = _find_frame(self.model, frame) if isinstance(frame, str) else None
        if fid is None:
            raise UnknownFrameError(str(frame), self.frame_names)
        return fid

    # ------------------------------------------------------------------ input checks
    def check_configuration(self, q: Sequence[float] | np.ndarray, *, batch: bool = True) -> np.ndarray:
        """Convert ``q`` to a float array and check its shape and values.

        Args:
            q: Shape (dof,) or, when `batch`, (N, dof) [rad or m].
            batch: Whether a 2-D array of configurations is accepted.

        Returns:
            A new float array of the same shape.

        Raises:
            InvalidConfigurationError: On a wrong shape or a NaN/infinite value.
        """
        try:
            arr = np.array(q, dtype=float, copy=True)
        except (TypeError, ValueError) as exc:
            raise InvalidConfigurationError(f"q must be numbers, got {q!r}") from exc
        ok = arr.ndim == 1 or (batch and arr.ndim == 2)
        if not ok or arr.shape[-1] != self.dof:
            want = f"({self.dof},)" + (f" or (N, {self.dof})" if batch else "")
            raise InvalidConfigurationError(
                f"q has shape {arr.shape}; {self.name} expects {want} for joints {', '.join(self.joint_names)}"
            )
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = np.argwhere(bad)[0]
            joint = self.joint_names[idx[-1]]
            raise InvalidConfigurationError(f"q holds {arr[tuple(idx)]} for joint {joint!r}; values must be finite")
        return arr

    def within_limits(self, q: np.ndarray, tol: float = 0.0) -> np.ndarray | bool:
        """Whether each configuration lies inside the position limits (widened by `tol`).

        Args:
            q: Shape (dof,) or (N, dof) [rad or m].
            tol: Allowed excess [rad or m].

        Returns:
            A bool for one configuration, a (N,) bool array for a batch.
        """
        arr = self.check_configuration(q)
        inside = np.all((arr >= self._lower - tol) & (arr <= self._upper + tol), axis=-1)
        return bool(inside) if arr.ndim == 1 else inside

    def check_limits(self, q: np.ndarray, *, context: str = "", tol: float = 0.0) -> None:
        """Raise if any joint of ``q`` lies outside its range.

        Raises:
            JointLimitError: Naming the first joint out of range, its value and range.
        """
        arr = self.check_configuration(q)
        rows = arr.reshape(-1, self.dof)
        for k, row in enumerate(rows):
            out = np.nonzero((row < self._lower - tol) | (row > self._upper + tol))[0]
            if out.size:
                j = int(out[0])
                where = context if arr.ndim == 1 else f"{context + ' ' if context else ''}configuration {k}"
                raise JointLimitError(self.joint_names[j], row[j], self._lower[j], self._upper[j], context=where)

    # ------------------------------------------------------------------ kinematics
    def pinocchio_configuration(self, q: np.ndarray) -> np.ndarray:
        """Joint values as Pinocchio's configuration vector of :attr:`model`, unchecked.

        A continuous joint takes two entries, its cosine and sine.
        """
        return self._pin_q(np.asarray(q, dtype=float))

    def _pin_q(self, q: np.ndarray) -> np.ndarray:
        if not self._has_continuous:
            return q
        out = np.empty(self.model.nq)
        for k, (kind, iq) in enumerate(zip(self.joint_kinds, self._idx_q)):
            if kind == "continuous":
                out[iq], out[iq + 1] = math.cos(q[k]), math.sin(q[k])
            else:
                out[iq] = q[k]
        return out

    def _placement(self, q: np.ndarray, fid: int) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, self._pin_q(q))
        return pin.updateFramePlacement(self.model, self.data, fid).homogeneous

    def fk(self, q: Sequence[float] | np.ndarray, frame: str | None = None) -> np.ndarray:
        """Pose of a frame (default: the tip) in the base frame.

        Args:
            q: Shape (dof,) or (N, dof) [rad or m].
            frame: Frame name; None is the tip.

        Returns:
            A (4, 4) homogeneous transform, or (N, 4, 4) for a batch [m].
        """
        arr = self.check_configuration(q)
        fid = self.frame_id(frame)
        if arr.ndim == 1:
            return self._placement(arr, fid).copy()
        return np.stack([self._placement(row, fid) for row in arr]) if len(arr) else np.empty((0, 4, 4))

    def tip_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tip position (3,) [m] and rotation (3, 3) for one configuration, without input checks.

        The solvers' inner loops use it on configurations they produced themselves; everyone else
        calls :meth:`fk`, which checks its input.

        Args:
            q: A float array of shape (dof,) [rad or m], finite (not checked).

        Returns:
            Copies of the tip's translation and rotation in the base frame.
        """
        pin.forwardKinematics(self.model, self.data, self._pin_q(q))
        placement = pin.updateFramePlacement(self.model, self.data, self.tip_frame_id)
        return placement.translation.copy(), placement.rotation.copy()

    def position(self, q: Sequence[float] | np.ndarray, frame: str | None = None) -> np.ndarray:
        """Position of a frame (default: the tip) in the base frame, shape (3,) or (N, 3) [m]."""
        return self.fk(q, frame)[..., :3, 3]

    def joint_positions(self, q: Sequence[float] | np.ndarray) -> np.ndarray:
        """Origins of the base, every chain joint and the tip, for drawing the arm.

        Args:
            q: Shape (dof,) [rad or m].

        Returns:
            Shape (dof + 2, 3) [m]: the base origin, each joint origin base to tip, the tip.
        """
        arr = self.check_configuration(q, batch=False)
        pin.forwardKinematics(self.model, self.data, self._pin_q(arr))
        tip = pin.updateFramePlacement(self.model, self.data, self.tip_frame_id).translation
        joints = [self.data.oMi[j].translation for j in range(1, self.model.njoints)]
        return np.array([np.zeros(3), *joints, tip])

    def jacobian(
        self,
        q: Sequence[float] | np.ndarray,
        frame: str | None = None,
        *,
        reference: Literal["world", "local", "local_world_aligned"] = "local_world_aligned",
    ) -> np.ndarray:
        """Geometric Jacobian of a frame (default: the tip), shape (6, dof).

        Rows are ``[v; omega]``: linear then angular velocity. With the default
        ``"local_world_aligned"`` reference, ``v`` is the velocity of the frame's origin and
        ``omega`` its angular velocity, both in base-frame axes, so ``v = J[:3] @ qd`` is
        the time derivative of :meth:`position`. ``"local"`` expresses both in the frame's own
        axes; ``"world"`` is Pinocchio's spatial (base-origin) convention.

        Args:
            q: Shape (dof,) [rad or m].
            frame: Frame name; None is the tip.
            reference: Which frame the twist is expressed in.

        Returns:
            The (6, dof) Jacobian [m/rad or m/m for v rows, rad/rad for omega rows].
        """
        arr = self.check_configuration(q, batch=False)
        fid = self.frame_id(frame)
        refs = {
            "world": pin.ReferenceFrame.WORLD,
            "local": pin.ReferenceFrame.LOCAL,
            "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        }
        if reference not in refs:
            raise InvalidArgumentError(f"unknown reference {reference!r}; valid: {', '.join(refs)}")
        jac = pin.computeFrameJacobian(self.model, self.data, self._pin_q(arr), fid, refs[reference])
        return np.array(jac, dtype=float).reshape(6, self.model.nv)  # a 1-joint arm's comes back flat

    def resolve_task(self, task: Task | None) -> Task:
        """The task a singularity measure uses: `task`, or by default pose or position.

        The default is ``"pose"`` (all 6 Jacobian rows) for arms with 6 or more joints and
        ``"position"`` (the 3 linear rows) for the others.

        Raises:
            InvalidArgumentError: On a task other than ``"position"`` or ``"pose"``.
        """
        if task is None:
            return "pose" if self.dof >= 6 else "position"
        if task not in ("position", "pose"):
            raise InvalidArgumentError(f"unknown task {task!r}; valid: position, pose")
        return task

    def conditioning(self, q: Sequence[float] | np.ndarray, task: Task | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Inverse condition number and manipulability together.

        The inverse condition number is that of the task Jacobian made dimensionless by the
        arm's :attr:`characteristic_length` L: the angular rows of a ``"pose"`` Jacobian are
        multiplied by L (a tip rotation of 1 rad counts like a translation of L) and the columns
        of prismatic joints by L (a travel of L counts like 1 rad). Both are then in metres per
        radian, so the ratio does not depend on the unit of length or the arm's size: the same
        arm scaled up or down has the same value in the same configuration (with the raw
        ``[v; omega]`` rows a small arm's translation rows look weak beside its rotation rows
        and a large arm's strong). A ``"position"`` Jacobian of revolute joints is unchanged by
        this. The manipulability is Yoshikawa's on the raw Jacobian, as :meth:`manipulability`.

        Args:
            q: Shape (dof,) or (N, dof) [rad or m].
            task: As for :meth:`manipulability`.

        Returns:
            ``(inverse_condition_number, manipulability)``, float arrays of shape () or (N,).
        """
        t = self.resolve_task(task)
        arr = self.check_configuration(q)
        rows = arr.reshape(-1, self.dof)
        inverse, manipulability = self.conditioning_of(*self.task_jacobians(rows, t), t)
        shape = () if arr.ndim == 1 else (len(rows),)
        return inverse.reshape(shape), manipulability.reshape(shape)

    def task_jacobians(self, q: np.ndarray, task: Task | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The tip's task Jacobians, raw and made dimensionless as in :meth:`conditioning`.

        Args:
            q: Configurations, shape (N, dof) [rad or m], not checked (for inner loops).
            task: As for :meth:`manipulability`.

        Returns:
            ``(raw, scaled)``, each of shape (N, m, dof) with m = 3 for ``"position"``, 6 for
            ``"pose"`` (raw in m/rad, m/m and rad/rad; scaled in m/rad).
        """
        t = self.resolve_task(task)
        model, data = self.model, self.data
        fid, ref = self.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        jacobian = pin.computeFrameJacobian
        jacs = np.empty((len(q), 6, model.nv))
        # Written in place row by row (a 1-joint arm's Jacobian comes back flat: reshaped).
        rows = (self._pin_q(row) for row in q) if self._has_continuous else q
        if model.nv == 1:
            for k, row in enumerate(rows):
                jacs[k] = np.reshape(jacobian(model, data, row, fid, ref), (6, 1))
        else:
            for k, row in enumerate(rows):
                jacs[k] = jacobian(model, data, row, fid, ref)
        return self.task_rows(jacs, t)

    def task_rows(self, jacs: np.ndarray, task: Task | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`task_jacobians` from the tip's geometric Jacobians, however computed.

        Args:
            jacs: Tip Jacobians as :meth:`jacobian` gives them, shape (N, 6, dof); not copied
                (the raw pose Jacobians returned are `jacs` itself).
            task: As for :meth:`manipulability`.

        Returns:
            ``(raw, scaled)`` as :meth:`task_jacobians`.
        """
        t = self.resolve_task(task)
        length = self._characteristic_length
        columns = self._column_scale
        if t == "position":
            jacs = jacs[:, :3]
            scaled = jacs * columns
        else:
            scaled = jacs * columns
            scaled[:, 3:] *= length
        return jacs, scaled

    def conditioning_of(
        self, raw: np.ndarray, scaled: np.ndarray, task: Task | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`conditioning` from :meth:`task_jacobians` (the same values, row by row).

        Returns:
            ``(inverse_condition_number, manipulability)``, each of shape (N,).
        """
        return self.conditioning_from(*self.task_singular_values(raw, scaled, task), task)

    def task_singular_values(
        self, raw: np.ndarray, scaled: np.ndarray, task: Task | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The singular values :meth:`conditioning` is computed from, largest first.

        Returns:
            Those of the scaled Jacobians and those the manipulability is the product of (the
            same array when :meth:`manipulability_divisor` is not None, else the raw Jacobians'),
            each of shape (N, min(m, dof)).
        """
        # One batched SVD; only the min(m, n) largest singular values: a 3x2 Jacobian has two.
        k = min(raw.shape[1:])
        s = np.linalg.svd(scaled, compute_uv=False)[:, :k]
        if self.manipulability_divisor(task) is not None:
            return s, s
        return s, np.linalg.svd(raw, compute_uv=False)[:, :k]

    def conditioning_from(
        self, s_scaled: np.ndarray, s_manipulability: np.ndarray, task: Task | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`conditioning` from :meth:`task_singular_values`.

        Returns:
            ``(inverse_condition_number, manipulability)``, each of shape (N,).
        """
        largest = s_scaled[:, 0]
        inverse = np.divide(s_scaled[:, -1], largest, out=np.zeros(len(s_scaled)), where=largest != 0.0)
        divisor = self.manipulability_divisor(task)
        manipulability = np.prod(s_manipulability, axis=1)
        if divisor is not None and divisor != 1.0:
            manipulability = manipulability / divisor
        return inverse, manipulability

    def manipulability_divisor(self, task: Task | None = None) -> float | None:
        """The product of the scaled Jacobian's singular values over the manipulability, if fixed.

        Returns:
            The divisor (1 for ``"position"``, ``L**3`` for ``"pose"`` with 6 or more joints),
            or None where :meth:`conditioning_of` takes the raw Jacobian's singular values
            (prismatic joints, or fewer than 6 joints for ``"pose"``).
        """
        t = self.resolve_task(task)
        if any(kind == "prismatic" for kind in self.joint_kinds):
            return None
        if t == "position":
            return 1.0
        # sqrt(det(D J J^T D)) = det(D) sqrt(det(J J^T)) for a wide Jacobian and row scales D.
        return self._characteristic_length**3 if self.dof >= 6 else None

    def manipulability(self, q: Sequence[float] | np.ndarray, task: Task | None = None) -> np.ndarray | float:
        """Yoshikawa manipulability of the tip, the product of the Jacobian's singular values.

        For a task Jacobian J (m x n) this is ``sqrt(det(J J^T))`` when m <= n and
        ``sqrt(det(J^T J))`` otherwise, so it is zero exactly at a singular configuration
        and positive elsewhere, also for arms with fewer joints than task dimensions.

        Args:
            q: Shape (dof,) or (N, dof) [rad or m].
            task: ``"position"`` (3 linear rows) or ``"pose"`` (all 6 rows, mixing m and rad);
                None picks ``"pose"`` for arms with 6 or more joints, else ``"position"``.

        Returns:
            A float, or a (N,) array for a batch.
        """
        value = self.conditioning(q, task)[1]
        return float(value) if value.ndim == 0 else value

    def inverse_condition_number(self, q: Sequence[float] | np.ndarray, task: Task | None = None) -> np.ndarray | float:
        """Smallest over largest singular value of the task Jacobian, in [0, 1].

        1 is isotropic, 0 singular; a condition number of 30 is an inverse of 1/30.

        Args:
            q: Shape (dof,) or (N, dof) [rad or m].
            task: As for :meth:`manipulability`.

        Returns:
            A float, or a (N,) array for a batch.
        """
        value = self.conditioning(q, task)[0]
        return float(value) if value.ndim == 0 else value

    def random_configurations(self, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
        """Configurations drawn uniformly within the position limits.

        Continuous joints (unbounded) are drawn from [-pi, pi).

        Args:
            rng: The generator to draw from (the global NumPy state is never touched).
            n: Number of configurations; None for a single one.

        Returns:
            Shape (dof,) or (n, dof) [rad or m].

        Raises:
            InvalidArgumentError: If `rng` is not a ``numpy.random.Generator`` or n < 0.
        """
        if not isinstance(rng, np.random.Generator):
            raise InvalidArgumentError(
                f"rng must be a numpy.random.Generator (e.g. numpy.random.default_rng(0)), got {type(rng).__name__}"
            )
        if n is not None and (not isinstance(n, (int, np.integer)) or n < 0):
            raise InvalidArgumentError(f"n must be a non-negative integer, got {n!r}")
        lo = np.where(np.isfinite(self._lower), self._lower, -math.pi)
        hi = np.where(np.isfinite(self._upper), self._upper, math.pi)
        size = (self.dof,) if n is None else (int(n), self.dof)
        return rng.uniform(lo, hi, size=size)
