"""The warnings of train and evaluate on what the rollouts and the data do to the learned
energy and entropy: an entropy that rises beyond the data's (:func:`entropy_rise_warning`) and
an energy that the data move, or that is constant to rounding (:func:`energy_change_warning`).
"""

from __future__ import annotations

from .._energy_along import ENERGY_ROUNDING_LIMIT


#: Above this excess of the entropy's rise along the rollouts over its rise along the data, in
#: units of its range over the data's states (``entropy_rise_over_data_spread``), train and
#: evaluate warn. Not a check of the verdict: a GENERIC model can make too much entropy. True
#: models rolled out on their own data give 2e-3 or less (zoo, reference experiments), but 0.68
#: where Crank–Nicolson's step is coarse for stiff heat conduction (a published-pendulum
#: stand-in at dt = 0.3): the rollout's entropy, not the field's, is judged.
ENTROPY_RISE = 1.0
#: ... or where it rises more than this many times its rise along the data over the same steps
#: (``entropy_rise_over_data_rise``): 0.91-1.11 on seven new-user checks' fits, 1.00 for the
#: zoo's true models; 4.5-7.3 on a gantry crane whose brake spans 290-330 K across the
#: trajectories and heats by about 0.5 K along each (its spread figure 0.05-0.09).
ENTROPY_RISE_RATIO = 2.0


def entropy_rise_warning(metrics: dict) -> list[str]:
    """A warning where the model's entropy outruns the data's along the rollouts: each entropy
    variable's rate can fit the data while their sum, the entropy production, is far too
    large, and S only grows, so the error adds up."""
    rise = metrics.get("entropy_rise_over_data_spread")
    times = metrics.get("entropy_rise_over_data_rise")
    said = ([f"rises {times:.3g} times as much as along the data over the same steps "
             "(entropy_rise_over_data_rise)"] if times is not None and times > ENTROPY_RISE_RATIO
            else [])
    if rise is not None and rise > ENTROPY_RISE:
        said.append(f"{'beyond it' if said else 'rises beyond its rise along the data'} by "
                    f"{rise:.3g} times its whole range over the data's states")
    if not said:
        return []
    leave = (", and its rollouts leave the data's range of S" if rise is not None
             and rise > ENTROPY_RISE else "")
    return [f"warning: along the rollouts the learned entropy {', '.join(said)}: the model "
            "makes entropy that the data do not show (each entropy variable's rate can fit "
            f"while their sum, the entropy production, does not){leave}. Judge it over short "
            "horizons; more trajectories, or M given where it is known (--friction "
            "file:M.npy), may help."]


#: Above this change of the learned E along an observed trajectory, beyond the noise on it
#: and over E's spread on the data, train and evaluate warn. Measured: 1.9e-3 to 4.1e-2 on the
#: zoo's fits to clean data (seven cases); 0.26 on a Duffing oscillator trained on neighbouring
#: pairs of data with 5 % noise, 6.7e-2 on the pairs the default spacing takes, 1.8e-2 clean.
ENERGY_CHANGE = 0.1


def energy_change_warning(metrics: dict) -> list[str]:
    """A warning where the learned E moves along the observed trajectories: GENERIC data keep
    the energy constant, and a model's own flow keeps its E constant, so an E that the data
    move is not the energy these data conserve."""
    rounding = metrics.get("energy_rounding_over_data_spread")
    if rounding is not None and rounding > ENERGY_ROUNDING_LIMIT:
        return [f"warning: the learned energy is constant over the data to rounding (its "
                f"rounding there is {rounding:.2g} of its spread; "
                "energy_rounding_over_data_spread), so its moves cannot be resolved and the "
                "energy figures are null: the model learned no energy (where L = 0 and S is "
                "given nothing fixes E's size, and M grad E = 0 is met by a vanishing E: "
                "README, Known limits), or one whose offset dwarfs its spread (--float64 "
                "resolves that). Judge the model by its rollouts and by degeneracy_M_gradE, "
                "which is relative."]
    change = metrics.get("energy_change_along_data_over_spread")
    if change is None or change <= ENERGY_CHANGE:
        return []
    return [f"warning: the learned energy changes along the observed trajectories by "
            f"{change:.2g} of its spread over the data, beyond the noise on them "
            "(energy_change_along_data_over_spread): a closed system keeps its energy "
            "constant, so this E is not the energy the data conserve. The model is off "
            "where the data go (too short a training, too few trajectories, noisy training "
            "data: README, Noisy data), or the system exchanges energy with something its "
            "state does not record. Do not read it as the system's energy."]
