"""fmpy as a co-simulation master of the boat and navigation FMUs, one job per process (as a
tool loads an FMU: pythonfmu's binaries do not share a process well); prints JSON.

    python fmpy_master.py loop NAV.fmu BOAT.fmu SCENARIO.toml SECONDS LOG.csv
    python fmpy_master.py bad-step NAV.fmu
    python fmpy_master.py parameter NAV.fmu NAME VALUE
"""

import json
import os
import sys

import numpy as np
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.fmi3 import FMU3Slave

BOAT_OUT = ("x", "y", "psi", "u", "v", "r", "u_dot", "v_dot", "r_dot", "nT_actual",
            "nS_actual")


class Fmu:
    """An FMU instance in fmpy, values by name, its log messages kept (FMI 2.0)."""

    def __init__(self, path, name):
        self.md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.v3 = self.md.fmiVersion == "3.0"
        self.messages = []
        kind = FMU3Slave if self.v3 else FMU2Slave
        self.fmu = kind(guid=self.md.guid, unzipDirectory=extract(path),
                        modelIdentifier=self.md.coSimulation.modelIdentifier,
                        instanceName=name)
        if self.v3:
            self.fmu.instantiate()
            return

        def logger(env, instance, status, category, message):
            self.messages.append((status, message.decode()))

        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)

    def set(self, **values):
        for name, value in values.items():
            vr = [self.vr[name]]
            if isinstance(value, str):
                self.fmu.setString(vr, [value])
            elif isinstance(value, int):
                (self.fmu.setInt32 if self.v3 else self.fmu.setInteger)(vr, [value])
            else:
                (self.fmu.setFloat64 if self.v3 else self.fmu.setReal)(vr, [float(value)])

    def get(self, *names):
        get = self.fmu.getFloat64 if self.v3 else self.fmu.getReal
        return np.array(get([self.vr[n] for n in names]), float)

    def close(self):
        """Terminate and free the instance; the binary stays loaded until the process ends."""
        self.fmu.terminate()
        (self.fmu.fmi3FreeInstance if self.v3 else self.fmu.fmi2FreeInstance)(self.fmu.component)

    def init(self):
        if self.v3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()


def loop(nav_path, boat_path, scenario_path, seconds, log_path):
    """Both FMUs as libcosim's fixed-step algorithm steps them: both step, then outputs go
    to inputs. The boat's state every 0.1 s."""
    from scenarios.cosim.system import boat_initial_values
    from scenarios.scenario_file import load_scenario

    boat, nav = Fmu(boat_path, "boat"), Fmu(nav_path, "navigation")
    boat.set(**boat_initial_values(load_scenario(scenario_path)))
    boat.init()
    nav.set(**dict(zip(BOAT_OUT, boat.get(*BOAT_OUT))), log_path=log_path)
    nav.init()
    states, h = [], 0.01
    for i in range(int(round(float(seconds) / h))):
        if i % 10 == 0:
            states.append(boat.get("x", "y", "psi", "u", "v", "r").tolist())
        boat.set(**dict(zip(("nT", "nS"), nav.get("nT", "nS"))))
        nav.set(**dict(zip(BOAT_OUT, boat.get(*BOAT_OUT))))
        boat.fmu.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
        nav.fmu.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
    for fmu in (nav, boat):
        fmu.close()
    return {"states": states}


def bad_step(nav_path):
    nav = Fmu(nav_path, "navigation")
    nav.init()
    try:
        nav.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.03)
        raised = False
    except Exception:  # fmpy's FMICallException for fmi2Error
        raised = True
    nav.close()
    return {"raised": raised, "messages": nav.messages}


def parameter(nav_path, name, value):
    nav = Fmu(nav_path, "navigation")
    nav.set(**{name: value})
    try:
        nav.init()
        raised = False
    except Exception:
        raised = True
    return {"raised": raised, "messages": nav.messages}


if __name__ == "__main__":
    job, args = sys.argv[1], sys.argv[2:]
    result = {"loop": loop, "bad-step": bad_step, "parameter": parameter}[job](*args)
    print(json.dumps(result), flush=True)
    # pythonfmu 0.7's FMI 2.0 binary can crash Python's teardown after fmpy used it (README,
    # "Known limits"); the results are out, so the process ends here
    os._exit(0)
