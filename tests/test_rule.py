"""The deployment rule (prlpid_fmi.deliver.choose) on hand-made evidence."""
import math
from types import SimpleNamespace

from prlpid_fmi.deliver.rule import Candidate, choose
from prlpid_fmi.report.verdict import verdict


def metrics(ise, tv=10.0, overshoot=5.0, terminated=False):
    return {"overall": {"ISE": ise, "TotalVariation": tv, "Overshoot": overshoot, "PeakDeviation": math.nan},
            "terminated": terminated}


def margins(ms, reliable=True, problems=None):
    """A margin estimate; an unreliable one is "varying" (impossible to measure) unless `problems` says otherwise."""
    problems = () if reliable else ("varying",) if problems is None else problems
    return SimpleNamespace(Ms=ms, reliable=reliable, problems=problems, note="; ".join(problems))


def cand(name, ise, ms=1.5, reliable=True, tv=10.0, terminated=False, mc=(), problems=None):
    return Candidate(name, metrics(ise, tv, terminated=terminated), list(mc), [margins(ms, reliable, problems)],
                     [0.0])


def test_the_better_robust_schedule_is_deployed():
    assert choose(cand("gain schedule", 0.9), cand("fixed PID", 1.0), 2.0).deploy == "gain schedule"


def test_a_schedule_above_the_ms_limit_or_chattering_or_diverging_or_not_better_is_refused():
    fixed = cand("fixed PID", 1.0)
    for schedule in (cand("gain schedule", 0.5, ms=2.5), cand("gain schedule", 0.5, tv=15.1),
                     cand("gain schedule", 0.5, terminated=True), cand("gain schedule", 1.0),
                     cand("gain schedule", 0.5, mc=[metrics(0.1, terminated=True)])):
        assert choose(schedule, fixed, 2.0).deploy == "fixed PID"
    # the Monte-Carlo set counts in the score: better on the evaluation, much worse on the samples
    worse = cand("gain schedule", 0.9, mc=[metrics(5.0)])
    assert choose(worse, cand("fixed PID", 1.0, mc=[metrics(1.0)]), 2.0).deploy == "fixed PID"


def test_an_eligible_schedule_is_deployed_where_the_fixed_pid_is_refused_whatever_their_ise():
    """A fixed PID above the Ms limit cannot be the bar a table must clear: a table that passes every check is
    deployed in its place even with a higher ISE and total variation; with a classical schedule in between, the
    classical one takes the refused fixed PID's place and the adaptive table is compared with it as usual."""
    from prlpid_fmi.deliver.rule import choose_among

    refused = cand("fixed PID", 1.0, ms=2.5)
    d = choose(cand("gain schedule", 1.2, tv=30.0), refused, 2.0)
    assert d.deploy == "gain schedule"
    assert d.reasons[0].startswith("The fixed PID is not deployable: ") and "deployed in its place" in d.reasons[-1]
    assert choose(cand("gain schedule", 1.2, ms=2.2), refused, 2.0).deploy == "none"
    d = choose_among(cand("gain schedule", 1.19), cand("classical gain schedule", 1.2), refused, 2.0)
    assert d.deploy == "classical gain schedule"  # the adaptive table does not beat it by 1 %
    assert choose_among(cand("gain schedule", 1.0), cand("classical gain schedule", 1.2), refused,
                        2.0).deploy == "gain schedule"


def test_nothing_is_deployed_when_neither_meets_the_limit_and_the_verdict_says_so():
    d = choose(cand("gain schedule", 0.5, ms=3.0), cand("fixed PID", 1.0, ms=2.2), 2.0)
    assert d.deploy == "none"
    text = verdict(d, cand("gain schedule", 0.5, ms=3.0), cand("fixed PID", 1.0, ms=2.2), 2.0)
    assert "Nothing here is safe to deploy" in text


def test_impossible_margins_neither_qualify_nor_disqualify_but_failed_ones_do():
    """robustness.status: a plant varying faster than the experiment ("varying") cannot be judged: the fixed PID
    stays deployable, the schedule is deployed on verified robustness only unless deploy.allow_unverified opts
    in; a loop that diverged, sat at a limit or was too lightly damped to settle has failed, whatever its
    estimate says."""
    unreliable = cand("gain schedule", 0.9, ms=40.0, reliable=False)
    fixed = cand("fixed PID", 1.0, ms=20.0, reliable=False)
    d = choose(unreliable, fixed, 2.0)
    assert d.deploy == "fixed PID" and unreliable.unverified and math.isnan(unreliable.worst_Ms)
    assert d.reasons == ("The gain schedule is not deployed: its robustness is not verified (1 of 1 Ms estimates "
                         "impossible to make: the plant varies faster than the margin experiment); "
                         "deploy.allow_unverified: true deploys it anyway.",)
    text = verdict(d, unreliable, fixed, 2.0)
    assert "could not be verified" in text and "Its worst Ms is not verified" in text
    d = choose(unreliable, fixed, 2.0, allow_unverified=True)
    assert d.deploy == "gain schedule"
    partly = Candidate("gain schedule", metrics(0.9), [], [margins(1.5), margins(40.0, reliable=False)], [0.0, 1.0])
    assert choose(partly, cand("fixed PID", 1.0), 2.0).deploy == "fixed PID"  # one impossible estimate is enough
    assert choose(partly, cand("fixed PID", 1.0), 2.0, allow_unverified=True).deploy == "gain schedule"
    diverged = cand("gain schedule", 0.9, ms=math.inf, reliable=False, problems=())
    assert choose(diverged, fixed, 2.0).deploy == "fixed PID"
    for kind in ("lightly_damped", "saturated"):  # failed even with an estimate inside the limit
        failed = cand("gain schedule", 0.9, ms=1.5, reliable=False, problems=(kind,))
        d = choose(failed, fixed, 2.0)
        assert d.deploy == "fixed PID" and "fails the robustness check" in d.reasons[0], kind


def test_the_advice_after_a_lost_schedule_names_a_setting_of_the_runs_gain_map():
    lost = choose(cand("gain schedule", 1.2), cand("fixed PID", 1.0), 2.0)
    assert lost.deploy == "fixed PID"
    anchored = verdict(lost, cand("gain schedule", 1.2), cand("fixed PID", 1.0), 2.0, "anchored")
    absolute = verdict(lost, cand("gain schedule", 1.2), cand("fixed PID", 1.0), 2.0, "absolute")
    assert "controller.anchor_bands" in anchored and "gain_mapping" not in anchored
    assert "controller.gain_mapping: anchored" in absolute and "anchor_bands" not in absolute


def test_a_schedule_must_beat_the_fixed_pid_by_one_percent_to_be_deployed():
    """1.5 % better: deployed; 0.5 % better: a tie (one set of gains is simpler than a table), the fixed PID."""
    fixed = cand("fixed PID", 2.0)
    assert choose(cand("gain schedule", 1.97), fixed, 2.0).deploy == "gain schedule"
    tie = choose(cand("gain schedule", 1.99), fixed, 2.0)
    assert tie.deploy == "fixed PID"
    assert "by 1% or more (1.99 vs 2)" in tie.reasons[0]


def test_the_verdict_gives_the_overshoot_itself_when_the_fixed_pid_has_none():
    schedule = Candidate("gain schedule", metrics(0.5, overshoot=4.0), [], [margins(1.5)], [0.0])
    fixed = Candidate("fixed PID", metrics(1.0, overshoot=0.0), [], [margins(1.5)], [0.0])
    text = verdict(choose(schedule, fixed, 2.0), schedule, fixed, 2.0)
    assert "its ISE is 0.50x the fixed PID's, its overshoot 4 % (fixed PID 0 %)" in text
    assert "peak deviation" not in text


def test_a_schedule_above_the_users_overshoot_limit_does_not_replace_a_fixed_pid_within_it():
    """deploy.max_overshoot 5 %: a schedule at 6.5 % (within the acceptance floor of 25 %) with 2 % less ISE is not
    deployed over a fixed PID at 4.5 %; where both are above the user's limit, ISE decides as before."""
    from prlpid_fmi.deliver.acceptance import Acceptance

    def checked(c, overshoot):
        c.acceptance = Acceptance(overshoot_pct=overshoot, user_overshoot_pct=5.0)
        return c

    fixed = checked(cand("fixed PID", 1.0), 4.5)
    kept = choose(checked(cand("gain schedule", 0.98), 6.5), fixed, 2.0)
    assert kept.deploy == "fixed PID"
    assert ("its overshoot 6.5 % is above deploy.max_overshoot (5 %) where the fixed PID's 4.5 % is within it"
            in kept.reasons[0])
    assert choose(checked(cand("gain schedule", 0.98), 5.0), fixed, 2.0).deploy == "gain schedule"  # at the limit
    both = choose(checked(cand("gain schedule", 0.98), 8.0), checked(cand("fixed PID", 1.0), 9.0), 2.0)
    assert both.deploy == "gain schedule"


def test_a_win_on_the_evaluation_that_does_not_carry_over_to_held_out_episodes_is_refused():
    """Held-out training-distribution episodes: the schedule must be no worse there (NaN = not measured: no check)."""
    def held_out(c, ise):
        c.holdout_ise = ise
        return c

    fixed = held_out(cand("fixed PID", 1.0), 4.0)
    assert choose(held_out(cand("gain schedule", 0.9), 4.0), fixed, 2.0).deploy == "gain schedule"  # a tie is enough
    lost = choose(held_out(cand("gain schedule", 0.9), 4.4), fixed, 2.0)
    assert lost.deploy == "fixed PID"
    assert lost.reasons == ("The gain schedule is not deployed: its win does not carry over: on held-out episodes of "
                            "the training distribution its ISE is 4.4 against the fixed PID's 4.",)
    diverged = choose(held_out(cand("gain schedule", 0.9), math.inf), fixed, 2.0)
    assert diverged.deploy == "fixed PID" and diverged.reasons[0].endswith("training distribution it diverged.")
    assert choose(held_out(cand("gain schedule", 0.9), 99.0), cand("fixed PID", 1.0), 2.0).deploy == "gain schedule"
    both = choose(held_out(cand("gain schedule", 0.9), math.inf), held_out(cand("fixed PID", 1.0), math.inf), 2.0)
    assert both.deploy == "gain schedule"  # no worse than the incumbent there; the verdict says that both diverged
    assert both.reasons[1] == ("On held-out episodes of the training distribution both it and the fixed PID diverged: "
                               "that check could not tell them apart, and neither holds every setpoint step of the "
                               "training distribution.")


def test_an_infinite_ms_is_said_in_words():
    d = choose(cand("gain schedule", 0.5, ms=math.inf), cand("fixed PID", 1.0), 2.0)
    assert d.deploy == "fixed PID"
    assert d.reasons == ("The gain schedule is not deployed: its loop fails the robustness check at 1 of 1 operating "
                         "points (at 0, failed: in the margin measurement the loop diverged or was held at an actuator "
                         "limit (Ms = ∞)).",)


def test_with_a_classical_schedule_the_adaptive_one_must_beat_it_and_it_must_beat_the_fixed_pid():
    """deliver.rule.choose_among: classical vs fixed PID first, then the adaptive schedule vs the winner, by the same
    rule (1 % ISE, TV, held-out, load IAE, Ms)."""
    from prlpid_fmi.deliver.rule import choose_among

    fixed = cand("fixed PID", 1.0)
    classical = cand("classical gain schedule", 0.6)
    assert choose_among(cand("gain schedule", 0.8), classical, fixed, 2.0).deploy == "classical gain schedule"
    d = choose_among(cand("gain schedule", 0.8), classical, fixed, 2.0)
    assert d.reasons == ("The classical gain schedule beats the fixed PID on ISE (0.6 vs 1) within the robustness and "
                         "effort limits.",
                         "The gain schedule is not deployed: it does not beat the classical gain schedule on ISE by "
                         "1% or more (0.8 vs 0.6).")
    assert choose_among(cand("gain schedule", 0.5), classical, fixed, 2.0).deploy == "gain schedule"
    # a classical schedule that does not beat the fixed PID leaves the adaptive one to beat the fixed PID
    weak = cand("classical gain schedule", 0.995)
    assert choose_among(cand("gain schedule", 0.8), weak, fixed, 2.0).deploy == "gain schedule"
    assert choose_among(cand("gain schedule", 0.999), weak, fixed, 2.0).deploy == "fixed PID"
    # robustness: a classical schedule above the Ms limit is not deployed, the fixed PID is
    assert choose_among(None, cand("classical gain schedule", 0.5, ms=2.5), fixed, 2.0).deploy == "fixed PID"
    assert choose_among(None, None, fixed, 2.0) == choose(None, fixed, 2.0)
    # neither classical nor fixed deployable: the adaptive schedule can still be, by the rule against the fixed PID
    d = choose_among(cand("gain schedule", 0.5), cand("classical gain schedule", 0.5, ms=3.0),
                     cand("fixed PID", 1.0, ms=3.0), 2.0)
    assert d.deploy == "gain schedule"


def test_held_out_total_variation_and_unsettled_steps_refuse_a_schedule():
    """A schedule that wins on ISE but moves the actuator more than 1.5x as much on the held-out episodes (the
    two-tank's 2.41x), or leaves more of their setpoint steps unsettled than the fixed PID, is not deployed."""
    def held(c, tv, unsettled):
        c.holdout_ise, c.holdout_tv, c.holdout_unsettled = 1.0, tv, unsettled
        return c

    fixed = held(cand("fixed PID", 1.0), 10.0, 1)
    d = choose(held(cand("gain schedule", 0.8), 24.1, 1), fixed, 2.0)
    assert d.deploy == "fixed PID" and d.reasons == (
        "The gain schedule is not deployed: on held-out episodes of the training distribution its control signal "
        "varies 2.4x as much as the fixed PID's (limit 1.5x).",)
    d = choose(held(cand("gain schedule", 0.8), 12.0, 2), fixed, 2.0)
    assert d.deploy == "fixed PID" and d.reasons == (
        "The gain schedule is not deployed: on held-out episodes of the training distribution it leaves a setpoint "
        "step unsettled in 2 episodes (the fixed PID: 1).",)
    assert choose(held(cand("gain schedule", 0.8), 14.9, 1), fixed, 2.0).deploy == "gain schedule"


def test_classical_schedule_setting_is_auto_or_a_boolean_with_one_message(tmp_path):
    """deploy.classical_schedule: auto, true or false (YAML reads on/off as booleans too); anything else is one line
    naming the key, the value and what was expected."""
    import pytest

    from prlpid_fmi.errors import ScenarioError
    from prlpid_fmi.scenario.load import load_scenario

    base = "plant:\n  fmu: FirstOrderUnstable\n  loops: [{input: u, output: y}]\n"
    for text, value in (("auto", "auto"), ("true", True), ("off", False)):
        path = tmp_path / f"{text}.yaml"
        path.write_text(base + f"deploy: {{classical_schedule: {text}}}\n")
        assert load_scenario(path).deploy.classical_schedule == value
    path = tmp_path / "bad.yaml"
    path.write_text(base + "deploy: {classical_schedule: maybe}\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == (f"{path}: deploy.classical_schedule: neither 'auto' nor true/false (got 'maybe'; "
                              "expected auto, true or false)")


def _design(**extra):
    from prlpid_fmi.tuning.design_result import DesignResult

    return DesignResult.from_json({"gains": {"Kp": [8.3], "Ti": [5.8], "Td": [62.0]},
            "structure": {"setpoint_weight": [0.0], "derivative_weight": [0.0], "measurement_filter_s": [72.3]},
            "design": {"objective": "load", "load_step": 0.02, "load_cost": 1.02, "load_optimum": 1.02, **extra}})


def test_the_design_section_names_the_limits_that_hold_the_design_and_what_was_kept():
    """The report's "How the fixed PID was designed": the active limits (fixed_pid.json design.active_limits) with
    their worst estimate and points; an infeasible overshoot trade says the load-optimal gains are kept (as
    tuning.fixed_pid does) and never claims a trade; setpoint weights that all diverged are said to be so."""
    from prlpid_fmi.report.markdown import design_section

    active = [{"limit": "max_sensitivity", "point": [370.0], "loop": 0, "value": 1.9999995, "bound": 2.0},
              {"limit": "max_noise_gain", "point": [345.0], "loop": 0, "value": 0.0199, "bound": 0.02},
              {"limit": "max_noise_gain", "point": [370.0], "loop": 0, "value": 0.019999, "bound": 0.02}]
    inf = float("inf")
    text = design_section(_design(active_limits=active, estimates=[{"point": [p]} for p in (320.0, 345.0, 370.0)],
                                  traded_for_overshoot={"load_cost": 0.94, "ISE": inf, "Overshoot": inf,
                                                        "feasible": False},
                                  setpoint_weights=[{"b": 0.0, "ISE": inf, "Overshoot": inf},
                                                    {"b": 0.5, "ISE": inf, "Overshoot": inf}]), ["T"])
    assert ("Limits that hold this design (its estimates within 1% of them): Ms 2.00 against deploy.max_sensitivity 2 "
            "(at T = 370); std(u) from the measurement noise 2.0% of the control span against deploy.max_noise_gain "
            "2.0% (at T = 345, T = 370).") in text
    assert "a larger limit gives a faster loop" in text and "an excursion past it" in text
    # Ms on its limit at every point (a linear plant): no word on the range's ends
    every = [{"limit": "max_sensitivity", "point": [p], "loop": 0, "value": 1.997, "bound": 2.0} for p in (-1.0, 0.0, 1.0)]
    text_linear = design_section(_design(active_limits=every, estimates=[{"point": [p]} for p in (-1.0, 0.0, 1.0)]),
                                 ["y"])
    assert "Ms 2.00 against deploy.max_sensitivity 2 (at y = -1, y = 0, y = 1)" in text_linear
    assert "spends all the robustness" in text_linear and "excursion past it" not in text_linear
    assert "gave up load rejection" not in text
    assert ("found none (the setpoint episodes of its best candidate diverged): the load-optimal gains are kept, with "
            "the setpoint weight of least overshoot (b = 0).") in text
    assert "diverged on every setpoint episode of the training distribution" in text
    # a feasible trade, no active limit, finite setpoint responses: the trade's sentence alone
    text = design_section(_design(traded_for_overshoot={"load_cost": 1.3 * 1.02, "ISE": 4.0, "Overshoot": 3.47,
                                                        "feasible": True},
                                  setpoint_weights=[{"b": 0.0, "ISE": 5.0, "Overshoot": 9.0}]), ["T"])
    assert "gave up load rejection (1.3x the optimum) for an overshoot of 3.47 %." in text
    assert "Limits that hold" not in text and "diverged" not in text
    # requirement 5 on the local models: gains within the load tolerance with less setpoint ISE, kept; a refinement the
    # FMU did not confirm says nothing
    refined = {"kept": True, "ISE": 3.0, "ISE_before": 4.0, "load_cost": 1.1 * 1.02, "Overshoot": 4.2}
    text = design_section(_design(setpoint_refined=refined), ["T"])
    assert ("gains searched on the identified local models for the least setpoint ISE replaced the load-optimal ones: "
            "setpoint ISE 0.75x theirs with their b, load IAE 1.1x the optimum, overshoot 4.2 % (both on the FMU).") in text
    assert "SIMC" not in text
    bounded = design_section(_design(setpoint_refined={**refined, "classical_bound": True}), ["T"])
    assert ("overshoot 4.2 % (both on the FMU); its load IAE was held no worse than SIMC's or AMIGO's PID tuned to the "
            "same Ms on the models.") in bounded
    assert "local models" not in design_section(_design(setpoint_refined={**refined, "kept": False}), ["T"])


def test_the_design_section_says_when_the_gains_were_replaced_to_follow_the_setpoint_episodes():
    """tuning.load_design step 5 in the report: what replaced the load-optimal gains (search or stabilising PID) with
    its load IAE against the optimum, and no claim that the load-optimal gains were kept; nothing found: they are."""
    from prlpid_fmi.report.markdown import design_section

    inf = float("inf")
    diverged = {"traded_for_overshoot": {"load_cost": 0.94, "ISE": inf, "Overshoot": inf, "feasible": False},
                "setpoint_weights": [{"b": 0.0, "ISE": inf, "Overshoot": inf}]}
    search = {"source": "search", "load_cost": 8.67, "ISE": 2.7e4, "Overshoot": 0.03, "feasible": True}
    text = design_section(_design(**diverged, followed_setpoints=search, load_cost=8.67), ["T"])
    assert "the load tolerance was dropped" in text and "(load IAE 8.5x the optimum, worst overshoot 0.03 %" in text
    assert "load-optimal gains are kept" not in text and "first b of the grid is kept" not in text
    assert "With the load-optimal gains the loop diverged on every setpoint episode" in text
    stabilising = {**search, "source": "stabilising PID", "Overshoot": 12.0, "feasible": False}
    text = design_section(_design(**diverged, followed_setpoints=stabilising), ["T"])
    assert "the stabilising PID of the setpoint search is kept" in text and "worst overshoot 12 %" in text
    text = design_section(_design(**diverged, followed_setpoints={**search, "source": None}), ["T"])
    assert "the load-optimal gains are kept. This plant's setpoint steps" in text
    assert "the load-optimal gains are kept, with the setpoint weight of least overshoot (b = 0)." in text
    # the overshoot limit met without the load tolerance, the load-optimal gains following the episodes
    text = design_section(_design(traded_for_overshoot={"load_cost": 1.3, "ISE": 5.0, "Overshoot": 12.0,
                                                        "feasible": False},
                                  setpoint_weights=[{"b": 0.0, "ISE": 5.0, "Overshoot": 11.0}],
                                  followed_setpoints={**search, "load_optimal_diverged": False, "load_cost": 2.04,
                                                      "Overshoot": 4.5}), ["T"])
    assert ("deploy.max_overshoot is a limit of the deployed controller and baseline.load_tolerance a preference, so the "
            "load tolerance was dropped") in text and "(load IAE 2x the optimum, worst overshoot 4.5 %" in text
    assert "gains are kept" not in text and "diverged" not in text
    text = design_section(_design(traded_for_overshoot={"load_cost": 1.3, "ISE": 5.0, "Overshoot": 12.0,
                                                        "feasible": False},
                                  setpoint_weights=[{"b": 0.0, "ISE": 5.0, "Overshoot": 11.0}],
                                  followed_setpoints={**search, "source": None, "load_optimal_diverged": False,
                                                      "feasible": False, "Overshoot": 9.0}), ["T"])
    assert "the load-optimal gains are kept, with the setpoint weight of least overshoot (b = 0)." in text
    assert "Without the load tolerance no gains met the overshoot limit either (its best: load IAE" in text
    # no gains within the load tolerance met the overshoot limit, but the search's best meets it: those gains are
    # kept (requirement 3 ranks above 4), not dropped for the setpoint ISE without a load bound
    text = design_section(_design(traded_for_overshoot={"load_cost": 1.21 * 1.02, "ISE": 5.0, "Overshoot": 3.41,
                                                        "feasible": False, "nearest_load_tolerance": True},
                                  setpoint_weights=[{"b": 0.0, "ISE": 5.0, "Overshoot": 11.0}]), ["T"])
    assert ("the gains nearest it that meet the overshoot limit are kept, load IAE 1.21x the optimum, overshoot "
            "3.41 %") in text and "found none" not in text and "dropped" not in text


def test_the_report_says_why_a_classical_schedule_was_not_built_or_was_blended():
    from prlpid_fmi.report.verdict import classical_note

    assert classical_note(None) == "" and classical_note({"built": False, "gain_variation": 1.0}) == ""
    assert classical_note({"built": True, "follow_blend": 1.0}) == ""
    assert classical_note({"built": False, "why": "the fixed PID does better: not built"}) == (
        "A classical gain schedule was considered and not built: the fixed PID does better: not built.")
    assert classical_note({"built": True, "follow_blend": 0.25}).startswith(
        "The classical gain schedule's rows are 0.25 of the way from the fixed PID to the local load designs")
