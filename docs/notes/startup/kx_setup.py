"""Kinetix set-up only: task building, then validation (validate_ued_config, run_warnings with the
step-key check), wall and CPU time and JAX compiles per phase."""
import sys, time, jax
COMP = [0, 0.0]
jax.monitoring.register_event_duration_secs_listener(
    lambda e, d, **k: (COMP.__setitem__(0, COMP[0] + 1), COMP.__setitem__(1, COMP[1] + d)) if e == "/jax/core/compile/backend_compile_duration" else None)
def phase(name, fn):
    w, c, n, t = time.perf_counter(), time.process_time(), COMP[0], COMP[1]
    out = fn()
    print(f"{name:28s} wall {time.perf_counter()-w:7.1f} s  cpu {time.process_time()-c:7.1f} s  compiles {COMP[0]-n} ({COMP[1]-t:.1f} s)", flush=True)
    return out
import kinetix_task
from remidi.engine.config import UEDConfig, ReMiDiConfig
from remidi.engine.run.validation import validate_ued_config, run_warnings
task = phase("task (user's make_task)", kinetix_task.make_task)
cfg = UEDConfig(num_updates=6, eval_every=2, checkpoint_every=2, num_envs=8, num_steps=16, score="pvl", eval_attempts=2,
                remidi=ReMiDiConfig(steps_per_buffer=2))
phase("validate_ued_config", lambda: validate_ued_config(cfg, "remidi", task))
phase("run_warnings(check_step)", lambda: run_warnings(cfg, "remidi", task, True))
