"""The kernels of the exact method, one name for them all: each engine's module re-exported.

:mod:`.segments` (closed forms, segment rows, buffers, the loop state), :mod:`.tables` (contact
tables, the Coulomb force, the median), :mod:`.ideal` (ideal motors, batches), :mod:`.roots`
(event roots), :mod:`.motors` (the motor law's closed form), :mod:`.lagging` (lagging or
rate-limited motors), :mod:`.sampled` (sampled closed loops), :mod:`.linearize` (the
estimators' kernels) and :mod:`.philox` (random numbers). ``load("core")`` loads them all
compiled; ``load("<engine>")`` loads one engine and the engines it calls.
"""

from __future__ import annotations

from .segments import (COMMAND, CROSS, DONE, EPS, FAILED_STEP, F_OFF, F_RATE, F_REL, F_T, F_TERR,
                       F_TSUM, F_V, INF, I_AT, I_CHUNK, I_HINT, I_J, I_MAXSTEPS, I_NEV, I_NEVAL,
                       I_NSEG, I_PIECE, I_ROUNDS, I_STARTED, I_STUCK, I_WINDOW, MAX_STEPS,
                       N_FSTATE, N_ISTATE, PAUSE, RATIO_INTEGRAL_SERIES, RELEASE, SATURATION,
                       STICK, ZENO, budget_code, dense_values, displacement, expm1_ratio,
                       expm1_ratio_integral, grown, ordered_within, pairwise_block, pairwise_sum,
                       push_event, push_segment, reach_time, samples, segment_value, sign)
from .tables import (SMALL, contact_table, coulomb_force, lowest_contact, median_edges, median_row,
                     net_force, sorted_landscape, sorted_steps, staircase_median, staircase_sums)
from .ideal import (at_breakpoint, batch, batch_scene, ideal_piece, ideal_run, piece_start)
from .roots import (ARITHMETIC_HALVINGS, BRENT_MAXITER, BRENT_RTOL, BRENT_XTOL, MAX_HALVINGS,
                    all_zero, bisect, brent_root, event_inflection, event_slope, event_value,
                    first_root, first_root_all, free_first_root, midpoint, newton_root,
                    polish_root, stuck_first_root)
from .motors import (M_AFTER, M_END, M_RAMP, M_START, M_U, motor_build, motor_coefficients,
                     motor_displacement, motor_speed, play_take_up_time, play_taken_up)
from .lagging import (N_PARAMS, P_COMPLIANCE, P_DAMPING, P_MARGIN, P_MASS, P_RAMP_GAP, P_RATE,
                      P_SPEED_BOUND, P_TAU, P_TOTAL, advance_dynamic, advance_outputs,
                      compliant_round, compliant_segment, dynamic_run, filippov, free_segment,
                      instant_events, piece_begin, quiet_piece, stuck_segment, tied_solution)
from .sampled import (EST_GIVEN, EST_TRUTH, LAW_GIVEN, LAW_TABLE, L_CARRY, L_HIGH, L_KI, L_KP,
                      L_LOW, L_PERIOD, L_REFERENCE, L_SHIFT, L_START, L_SWITCH, S_HINT, S_REL,
                      S_STUCK, S_T, S_V, S_X, fresh_counters, ideal_period, lagging_period,
                      law_output, sampled_batch, sampled_steps, sensor_read)
from .linearize import (contains, cross_gains, flip_signs, gathered_sum, kalman_step,
                        linearize_step, period_bounds, release_force, stick_group, stuck_stretch,
                        window_line)
from .philox import (DOUBLE_UNIT, LOW32, PHILOX_M0, PHILOX_M1, PHILOX_W0, PHILOX_W1, SHIFT11,
                     SHIFT32, mulhilo, philox_block, philox_uniform)
from . import ideal, lagging, linearize, motors, philox, roots, sampled, segments, tables

#: The engine modules, in the order they build on each other.
ENGINES = (segments, tables, roots, motors, philox, ideal, lagging, linearize, sampled)

#: Every engine's own kernels and their numba options (toolkit._compiled.load binds them here).
KERNELS = {name: options for engine in ENGINES for name, options in engine.KERNELS.items()
           if getattr(vars(engine)[name], "py_func", vars(engine)[name]).__module__ == engine.__name__}
