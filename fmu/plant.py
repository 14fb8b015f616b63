"""`FmuBoat`: the boat FMU (FMI 2.0 or 3.0) stepped from Python through fmpy, cheaply.

Scenario runs step the plant thousands of times at 10 Hz; each `step` is three C calls
(set inputs, doStep, get outputs) on preallocated ctypes arrays, bypassing fmpy's per-call
Python wrappers. Errors the FMU reports are raised as `InputError` with the FMU's own message.
"""

from __future__ import annotations

import ctypes
import shutil
from pathlib import Path

import numpy as np

from controller.errors import InputError
from controller.model import CURRENT_NAMES, INPUT_NAMES, STATE_NAMES
from controller.params import PARAM_NAMES, BoatParams

from .variables import OUTPUT_NAMES, VR

OUTPUT_INDEX = {name: i for i, name in enumerate(OUTPUT_NAMES)}
"""Column of each output in the array `FmuBoat.step` returns."""

_OK, _WARNING = 0, 1


def _vr_array(names) -> ctypes.Array:
    return (ctypes.c_uint32 * len(names))(*(VR[n] for n in names))


class FmuBoat:
    """One instance of the boat FMU.

    `FmuBoat(path)` loads and instantiates; `setup(...)` sets parameters, initial state and
    current and initializes; `step(nT, nS, dt)` advances and returns the outputs
    (`OUTPUT_NAMES` order: x, y, psi, u, v, r, u_dot, v_dot, r_dot, nT_actual, nS_actual).
    """

    def __init__(self, fmu_path: str | Path, instance_name: str = "boat",
                 logging_on: bool = False):
        from fmpy import extract, read_model_description

        fmu_path = Path(fmu_path)
        if not fmu_path.is_file():
            raise InputError(f"{fmu_path}: no such FMU file")
        self.path = fmu_path
        self.messages: list[str] = []
        self._description = read_model_description(str(fmu_path))
        self.fmi_version = int(self._description.fmiVersion[0])
        self._unzipped = extract(str(fmu_path))
        self._slave = None
        kwargs = dict(
            guid=self._description.guid, unzipDirectory=self._unzipped,
            modelIdentifier=self._description.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )
        try:
            if self.fmi_version == 2:
                self._instantiate2(kwargs, logging_on)
            else:
                self._instantiate3(kwargs, logging_on)
        except Exception:
            self.close()
            raise
        self._bind()
        self._set_clock(0.0)
        self._initialized = False

    # -- instantiation ------------------------------------------------------------------
    def _collect(self, status: int, category: bytes | None, message: bytes | None) -> None:
        text = (message or b"").decode("utf-8", "replace")
        if self.fmi_version == 2:
            text = text.replace("%%", "%")  # our FMI 2.0 wrapper doubles '%' (printf format)
        self.messages.append(text)
        del self.messages[:-100]  # keep the last hundred

    def _instantiate2(self, kwargs, logging_on: bool) -> None:
        # Our own callbacks without fmpy's logger proxy: that proxy keeps one process-wide
        # target, which a second FMU (or a freed instance) would redirect or leave dangling.
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackFreeMemoryTYPE, fmi2CallbackLoggerTYPE)

        def logger(env, name, status, category, message):
            self._collect(status, category, message)

        libc = ctypes.CDLL(None)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(libc.calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(libc.free)
        self._keep = (logger, callbacks)
        self._slave = FMU2Slave(**kwargs)
        self._slave.instantiate(callbacks=callbacks, loggingOn=logging_on)

    def _instantiate3(self, kwargs, logging_on: bool) -> None:
        from fmpy.fmi3 import FMU3Slave

        def log_message(env, status, category, message):
            self._collect(status, category, message)

        self._keep = (log_message,)
        self._slave = FMU3Slave(**kwargs)
        self._slave.instantiate(loggingOn=logging_on, logMessage=log_message)

    def _bind(self) -> None:
        """Raw C entry points and preallocated arrays for the hot path."""
        dll, v = self._slave.dll, self.fmi_version
        self._component = ctypes.c_void_p(self._slave.component)
        self._c_set = getattr(dll, f"fmi{v}SetReal" if v == 2 else "fmi3SetFloat64")
        self._c_get = getattr(dll, f"fmi{v}GetReal" if v == 2 else "fmi3GetFloat64")
        self._c_step = getattr(dll, f"fmi{v}DoStep")
        self._in_vr = _vr_array(INPUT_NAMES)
        self._in = (ctypes.c_double * 2)()
        self._out_vr = _vr_array(OUTPUT_NAMES)
        self._out = (ctypes.c_double * len(OUTPUT_NAMES))()
        self._out_view = np.frombuffer(self._out, dtype=float)
        if v == 3:
            self._flags = [ctypes.c_bool() for _ in range(3)]
            self._last_time = ctypes.c_double()
            self._flag_refs = [ctypes.byref(f) for f in self._flags] + [
                ctypes.byref(self._last_time)]

    def _fail(self, what: str):
        detail = self.messages[-1] if self.messages else "no message from the FMU"
        raise InputError(f"FMU {self.path.name}: {what}: {detail}")

    def _check(self, status: int, what: str) -> None:
        if status > _WARNING:
            self._fail(what)

    # -- values -------------------------------------------------------------------------
    def set_values(self, values: dict[str, float]) -> None:
        """Set variables by name (parameters, inputs)."""
        unknown = [n for n in values if n not in VR]
        if unknown:
            raise InputError(f"FMU: unknown variable(s) {', '.join(unknown)}")
        n = len(values)
        vr = (ctypes.c_uint32 * n)(*(VR[k] for k in values))
        vals = (ctypes.c_double * n)(*(float(x) for x in values.values()))
        args = (self._component, vr, n, vals) + ((n,) if self.fmi_version == 3 else ())
        self._check(self._c_set(*args), "setting " + ", ".join(values))

    def get_values(self, names) -> np.ndarray:
        names = list(names)
        n = len(names)
        vr = (ctypes.c_uint32 * n)(*(VR[k] for k in names))
        vals = (ctypes.c_double * n)()
        args = (self._component, vr, n, vals) + ((n,) if self.fmi_version == 3 else ())
        self._check(self._c_get(*args), "getting " + ", ".join(names))
        return np.array(vals)

    def set_params(self, params: BoatParams) -> None:
        self.set_values(dict(zip(PARAM_NAMES, params.as_vector())))

    def set_current(self, north_mps: float, east_mps: float) -> None:
        self.set_values(dict(zip(CURRENT_NAMES, (north_mps, east_mps))))

    # -- lifecycle ----------------------------------------------------------------------
    def setup(self, params: BoatParams | None = None, state0=None, actuators0=(0.0, 0.0),
              current=(0.0, 0.0), rate_max=(0.0, 0.0), internal_step: float | None = None,
              start_time: float = 0.0, stop_time: float | None = None) -> np.ndarray:
        """Set parameters, initial state [x, y, psi, u, v, r], actuators, current; initialize.

        Returns the outputs at the start time. `rate_max` in %/s (0 = no limit).
        """
        values: dict[str, float] = {}
        if params is not None:
            values.update(zip(PARAM_NAMES, params.as_vector()))
        if state0 is not None:
            values.update(zip((f"{n}0" for n in STATE_NAMES), np.asarray(state0, float)))
        values.update(zip((f"{n}0" for n in INPUT_NAMES), actuators0))
        values.update(zip(CURRENT_NAMES, current))
        values.update(zip(("dnT_max", "dnS_max"), rate_max))
        if internal_step is not None:
            values["internal_step"] = internal_step
        self.set_values(values)
        s = self._slave
        try:
            if self.fmi_version == 2:
                s.setupExperiment(startTime=start_time, stopTime=stop_time)
                s.enterInitializationMode()
            else:
                s.enterInitializationMode(startTime=start_time, stopTime=stop_time)
            s.exitInitializationMode()
        except Exception:
            self._fail("initialization failed")
        self._set_clock(float(start_time))
        self._initialized = True
        return self.outputs()

    def outputs(self) -> np.ndarray:
        args = (self._component, self._out_vr, len(self._out), self._out)
        args += (len(self._out),) if self.fmi_version == 3 else ()
        self._check(self._c_get(*args), "getting the outputs")
        return self._out_view.copy()

    def step(self, nT: float, nS: float, dt: float) -> np.ndarray:
        """Hold the commands [nT, nS] (percent) for `dt` seconds; return the outputs at the end."""
        self._in[0] = nT
        self._in[1] = nS
        if self.fmi_version == 2:
            status = self._c_set(self._component, self._in_vr, 2, self._in)
        else:
            status = self._c_set(self._component, self._in_vr, 2, self._in, 2)
        if status > _WARNING:
            self._fail(f"setting the commands nT = {nT!r}, nS = {nS!r}")
        if self.fmi_version == 2:
            status = self._c_step(self._component, self.time, dt, 1)
        else:
            status = self._c_step(self._component, self.time, dt, True, *self._flag_refs)
        if status > _WARNING:
            self._fail(f"doStep at t = {self.time!r} over {dt!r} s")
        self._advance_clock(dt)
        return self.outputs()

    def _advance_clock(self, dt: float) -> None:
        """time = anchor + n * dt while dt stays the same: no drift over thousands of steps."""
        if dt != self._dt:
            self._anchor, self._n, self._dt = self.time, 0, dt
        self._n += 1
        self.time = self._anchor + self._n * dt

    def get_state(self):
        """An opaque snapshot of the whole FMU state (free it with `free_state`)."""
        return self._slave.getFMUState() if self.fmi_version == 3 else self._slave.getFMUstate()

    def set_state(self, state) -> None:
        if self.fmi_version == 3:
            self._slave.setFMUState(state)
        else:
            self._slave.setFMUstate(state)
        self._set_clock(float(self.get_values(["time"])[0]))

    def _set_clock(self, time: float) -> None:
        self.time, self._anchor, self._n, self._dt = time, time, 0, None

    def free_state(self, state) -> None:
        if self.fmi_version == 3:
            self._slave.freeFMUState(state)
        else:
            self._slave.freeFMUstate(state)

    def serialize_state(self, state) -> bytes:
        if self.fmi_version == 3:
            return bytes(self._slave.serializeFMUState(state))
        return bytes(self._slave.serializeFMUstate(state))

    def deserialize_state(self, data: bytes):
        if self.fmi_version == 3:
            return self._slave.deserializeFMUState(data)
        return self._slave.deSerializeFMUstate(data)

    def reset(self) -> None:
        """FMI reset: every variable back to its start value, time back to the start."""
        self._slave.reset()
        self._set_clock(0.0)
        self._initialized = False

    def close(self) -> None:
        """Free the instance and delete the unpacked FMU."""
        if self._slave is not None:
            try:
                if self._initialized:
                    self._slave.terminate()
            except Exception:
                pass
            self._slave.freeInstance()
            self._slave = None
        if getattr(self, "_unzipped", None):
            shutil.rmtree(self._unzipped, ignore_errors=True)
            self._unzipped = None

    def __enter__(self) -> "FmuBoat":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass
