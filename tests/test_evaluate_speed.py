"""FrictionModel.evaluate, made fast (issue 14 item 3), computes what it computed before: every base
law (and its degraded forms), every amplitude law of a line (with and without a speed range and a
load coefficient) and every term kind, at random inputs of both directions, v = 0 and speeds
either side of each speed-range edge.

Known answers: ``PINNED`` holds what evaluate returned before the change (gearspec 0.5.dev, commit
1506028, the per-direction masks and one ``evaluate_term`` per line), printed with 17 digits by
:func:`_pin_cases` below; :func:`_reference` is that algorithm, kept here, for many more points.
No timing here: the speed is measured by ``benchmarks/bench_evaluate.py``.
"""
import math

import numpy as np
import pytest

from gearspec.errors import InputError
from gearspec.model import LAWS, FrictionModel, Harmonic
from gearspec.terms import TERMS, AMPLITUDE_LAWS, evaluate_term
from term_examples import example_term, law_parameters



def _lines(rng, with_load):
    """One line per amplitude law (exp twice: once with decay 0, as SILO4 Table 2's first line),
    speed ranges on some, a load coefficient on one when ``with_load``."""
    out = []
    for i, law in enumerate(AMPLITUDE_LAWS + ("exp",)):
        h = {"frequency": [1 / (2 * math.pi), 0.0113682, 3 / (2 * math.pi), 2.3, 0.000554547][i],
             "amplitude": rng.uniform(0.01, 0.05), "decay": 0.0 if i == 4 else rng.uniform(0.005, 0.2),
             "phase": rng.uniform(-3, 3), "law": law}
        if i in (0, 2, 3):
            h["speed_range"] = [rng.uniform(0.3, 2.0), rng.uniform(20.0, 60.0)]
        if law == "rational" and with_load:
            h["load_coefficient"] = 1e-4
        out.append(h)
    return out


def law_model(law, seed=0, degraded=False):
    """A model of ``law``, different parameters and lines per direction; ``degraded``: its
    optional parameters None (not identified) in the negative direction."""
    rng = np.random.default_rng(seed)
    spec = LAWS[law]
    dirs = {}
    for d in ("positive", "negative"):
        vals = law_parameters(spec, rng, degraded and d == "negative")
        dirs[d] = {**vals, "harmonics": _lines(rng, spec.needs_load)[: 5 - 2 * (d == "negative")]}
    return FrictionModel(law, dirs["positive"], dirs["negative"], name=f"test {law}")


def term_model(kind):
    """A direction-dependent Coulomb + viscous base with the term for both directions and once more
    for the negative one only."""
    t = example_term(kind)
    return law_model("coulomb_viscous", seed=3).with_terms(t, {**t, "direction": -1})


def inputs(model, n, seed=1):
    """Random inputs: theta over +-300 rad, |v| log-uniform 1e-3..1e3 of both signs, every
    speed-range edge approached from both sides in both directions, v = 0 and +-1e-12; load,
    temperature, time, acceleration, two runs."""
    rng = np.random.default_rng(seed)
    v = rng.choice([-1.0, 1.0], n) * 10 ** rng.uniform(-3, 3, n)
    edges = [x for p in model.directions.values() for h in p.harmonics if h.speed_range for x in h.speed_range]
    near = np.array([s * e * f for e in edges[:2] for s in (-1, 1) for f in (1 - 1e-9, 1 + 1e-9)])
    v = np.concatenate([v, near, [0.0, 1e-12, -1e-12]])
    m = len(v)
    return dict(theta=rng.uniform(-300, 300, m), v=v, load=rng.uniform(-30, 30, m),
                temperature=rng.uniform(-10, 90, m), t=np.sort(rng.uniform(0, 100, m)),
                acc=rng.uniform(-100, 100, m), run=np.repeat([0, 1], [m // 2, m - m // 2]))


#: what evaluate returned before it was made fast, at ``inputs(model, 12)`` (see the module docstring)
PINNED = {
    'law none': [-0.07606902325766425, 0.0678161719736583, -0.06352696712704962, 0.07262524777006527,
        -0.03126837758221909, 0.03014664301313062, -0.011061315382744533, -0.021925865839344038,
        0.005215503704084707, -0.0197091640798768, 0.011954736819787391, 0.031331680623180494, 0.057536279586791264,
        0.03604610362990162, -0.09159268437408566, 0.03073294597050985, -0.02458267049306238, -0.009582623882728236,
        0.02296044185346371, -0.07306603103833065, 0.0, 0.05875019453398818, 0.028137551108131237],
    'law coulomb_viscous': [-0.2890920624353536, 0.1582583788753732, 0.21463991787648107, 0.19675033640589315,
        -0.28288790286928683, -0.2498389149678967, 0.25911761299590946, 0.35156363142155306, -0.23051277634735384,
        -0.25255142599925756, 0.1850941889893841, -0.26680927728147763, -0.3159439435030501, -0.2473226091044115,
        0.31088591258668563, 0.23479590755377494, -0.2896641191754105, -0.28833312125297217, 0.2725725584821881,
        0.28936224156598817, 0.0, 0.19507876211682348, -0.32639040638152883],
    'law stribeck': [-0.3336649535640724, 0.3097288080010484, 0.24572573079713958, 0.2917738681473816,
        -0.22269587832339682, -0.3049386004138648, 0.13472747954108816, 0.27999556201213294, -0.3228297689131655,
        -0.20568062961003347, 0.3275937738692465, -0.3244934679759249, -0.24138111504231516, -0.2478891079239104,
        0.1572146365633565, 0.18058863426368682, -0.24333337817948272, -0.25844144003913644, 0.27198360344379685,
        0.22421416858254978, 0.0, 0.2090755279417407, -0.23342090756162093],
    'law silo4': [-0.3336649535640724, 0.3097288080010484, 0.24572573079713958, 0.2917738681473816,
        -0.22269587832339682, -0.3049386004138648, 0.13472747954108816, 0.27999556201213294, -0.3228297689131655,
        -0.20568062961003347, 0.3275937738692465, -0.3244934679759249, -0.24138111504231516, -0.2478891079239104,
        0.1572146365633565, 0.18058863426368682, -0.24333337817948272, -0.25844144003913644, 0.27198360344379685,
        0.22421416858254978, 0.0, 0.2090755279417407, -0.23342090756162093],
    'law lola8': [-36.67137138358101, 0.42217582028748873, 0.7689469397526496, 0.6470731979100198,
        -0.5394464104979865, -0.3252298343559513, 0.39189047295650503, 11.213858935078337, -0.6529553695589185,
        -0.4690015683143983, 0.6455823353098813, -0.7431684587240973, -0.6932831790280216, -0.6538679343647957,
        0.6179800143869549, 0.5876538173548923, -9.380422830359551, -9.79457434747252, 0.6539876893002599,
        3.2291214436259925, 0.0, 0.3581102036528758, -0.43797180260152774],
    'law lola11': [-0.5599071537568638, 0.32153630836298797, 0.4827735178940503, 0.5232120389888087,
        -0.2910331853971898, -0.25642774819582825, 0.3875061637423594, 0.722774888287087, -0.3797697123778152,
        -0.35268316269065164, 0.42928890057488595, -0.3803934796785956, -0.3875158237527434, -0.4538264317849351,
        0.4846900802779559, 0.42356573776310386, -0.5161494555520937, -0.5188903391683322, 0.2797095785032471,
        0.5848151742117849, 0.0, 0.24241429859653124, -0.3688579459683084],
    'law coulomb_viscous degraded': [-0.1758649237421696, 0.2627187605162125, 0.09243900023353384,
        0.18083324076932378, -0.17616439563443587, -0.1978181656852091, 0.21894929893380313, 0.3028533328177766,
        -0.20506092086760075, -0.23599389579382696, 0.17479838022446265, -0.17866529826284752, -0.17039338604646553,
        -0.2435857655949536, 0.12166938908462865, 0.21448567088572842, -0.19402069234921274, -0.1771459287483171,
        0.17444606666354093, 0.2388741790710175, 0.0, 0.2410751291772118, -0.16594542480493815],
    'law stribeck degraded': [-0.05712136045675624, 0.2801312122877569, 0.19052839414789577, 0.32581077318292295,
        -0.05595173302807229, -0.04706662059403189, 0.22322436110342792, 0.2098714843032161, -0.06285318801069756,
        -0.05969450907922513, 0.3150384419117794, -0.01751472285982212, -0.025168064230793923, -0.12038514195409689,
        0.20227231887364203, 0.23683147750705694, -0.03438616408430177, -0.03068903259293618, 0.24625904088495668,
        0.20279932482680874, 0.0, 0.23119488706523778, -0.021027238792261673],
    'law silo4 degraded': [-0.05712136045675624, 0.2801312122877569, 0.19052839414789577, 0.32581077318292295,
        -0.05595173302807229, -0.04706662059403189, 0.22322436110342792, 0.2098714843032161, -0.06285318801069756,
        -0.05969450907922513, 0.3150384419117794, -0.01751472285982212, -0.025168064230793923, -0.12038514195409689,
        0.20227231887364203, 0.23683147750705694, -0.03438616408430177, -0.03068903259293618, 0.24625904088495668,
        0.20279932482680874, 0.0, 0.23119488706523778, -0.021027238792261673],
    'law lola11 degraded': [-0.5787796847352239, 0.16657921156249228, 0.46653531633125367, 0.5660916961859812,
        -0.25431185412184865, -0.1828784641171119, 0.40907487651264357, 0.6525497616907507, -0.3551344414609583,
        -0.2987303310023275, 0.3756895367000683, -0.44357591068422875, -0.44856211846132404, -0.29520354441757063,
        0.701814173742969, 0.5497311594931015, -0.5564164002950474, -0.5659819222646453, 0.3330391813008645,
        0.533385836408602, 0.0, 0.18646375344819213, -0.40351901760461506],
    'term backlash': [-0.16522506832183836, 0.0738475123001947, 0.023642452494538262, 0.09363997902629294,
        -0.14455998018701474, -0.08737118332990264, 0.08258440865841052, 0.1456757026945367, -0.07342685366068538,
        -0.0800585254654926, 0.06779743354651217, -0.087123574871956, -0.11668803305739087, -0.1288232145413808,
        0.10322580021530796, 0.08889787579988684, -0.17498528245325284, -0.16011431714012347, 0.06510686823055643,
        0.060154972285452364, 0.0, 0.06730756444205732, -0.14800632247022902],
    'term cogging': [-0.17241642905994659, 0.07730216791857276, 0.025907336707978183, 0.09762896467992817,
        -0.13812819971369308, -0.08254347823946516, 0.07945721186500909, 0.14940622745585422, -0.07836456902182823,
        -0.08432381149326167, 0.07167378020442769, -0.08011926766257828, -0.12445142129819659, -0.12090532791959141,
        0.10098646432962785, 0.08881707493372476, -0.17905281315239002, -0.1605807770765218, 0.06899187732535228,
        0.06350866772399641, -0.0029873363972326423, 0.06730782532403284, -0.14894256291532812],
    'term drift': [-0.16334156022399798, 0.07390672466726796, 0.024287525159279275, 0.09442569780803665,
        -0.14648591788930979, -0.09023549261602919, 0.08420935578591153, 0.14784308436010635, -0.07826274813948764,
        -0.08556146539542543, 0.0706016762453775, -0.09304869811629572, -0.12311180934196997, -0.1354477495169289,
        0.10766249311199251, 0.0942192269748885, -0.185648481373984, -0.17119163736149134, 0.07102023858333385,
        0.06640791166621475, 0.0, 0.07498076949847932, -0.16592914627260155],
    'term hysteresis': [-0.16522506832183836, 0.0738475123001947, 0.023642452494538262, 0.09363997902629294,
        -0.14455998018701474, -0.08737118332990264, 0.08258440865613322, 0.1456757026945367, -0.07342685366068538,
        -0.0800585254654926, 0.06779743354651217, -0.087123574871956, -0.11668803305739087, -0.1288232145413808,
        0.10322580021530796, 0.08889787579988684, -0.17498528245325284, -0.16011431714012347, 0.06510686823055643,
        0.060154972285452364, 0.0, 0.06730756444205732, -0.14800632247022902],
    'term inertia': [-0.4569841076493151, -0.18223844426522573, -0.12167567610741979, 0.2515170985527249,
        0.09291230463268288, -0.5329633285492994, 0.008327509515267062, 0.09822853946501445, 0.12455424197366755,
        -0.13294376981299394, 0.11970842964183102, 0.3204979494587749, 0.15508029931745362, -0.29081449833111006,
        0.07226358582199853, 0.009517617613890791, -0.6433036856452168, -0.5162244642352476, -0.06460923840296494,
        -0.05136469035316631, -0.11217128470803739, 0.11332739419382855, 0.41802164827347665],
    'term load_coulomb': [-0.5883844744986264, 0.1296121231627651, 0.16758398385220433, 0.2975688916451382,
        -0.15595503801282598, -0.10043784468974225, 0.23440253327971725, 0.35692248122356274, -0.45697891660381773,
        -0.30000281266940115, 0.24005559847939284, -0.45718406404779366, -0.4795250264188269, -0.49923450327274055,
        0.3542942297972003, 0.30203406037212893, -0.608525477866455, -0.6119588328400202, 0.08196103661528231,
        0.19572593911722141, 0.0, 0.15474010178702602, -0.4118975826806607],
    'term load_viscous': [-1.7311810615067391, 0.07448374133631966, 0.035066190546069936, 0.09365191597902917,
        -0.15969054627385673, -0.08825647118542913, 0.08316220383585474, 0.6000589455104556, -0.07443855724824108,
        -0.0846861702396411, 0.0678413361212783, -0.09100517352593414, -0.13172858138095592, -0.1441777373734855,
        0.11363324740712837, 0.0977329316200555, -0.8541182275589623, -0.8679206532940102, 0.0915086209019948,
        0.2725244622047842, 0.0, 0.06730756444206082, -0.14800632247023957],
    'term offset': [-0.18522506832183838, 0.06384751230019471, 0.013642452494538262, 0.08363997902629294,
        -0.16455998018701476, -0.10737118332990263, 0.07258440865841052, 0.1356757026945367, -0.09342685366068537,
        -0.10005852546549258, 0.05779743354651217, -0.10712357487195599, -0.13668803305739088, -0.1488232145413808,
        0.09322580021530796, 0.07889787579988684, -0.19498528245325286, -0.1801143171401235, 0.05510686823055643,
        0.05015497228545236, -0.01, 0.05730756444205732, -0.16800632247022904],
    'term periodic': [-0.19945526303235095, 0.09297308030061961, 0.007874926010021772, 0.11202411645721957,
        -0.10901208687956462, -0.04847702847984643, 0.07621820969856617, 0.14212940359981655, -0.11251787482238082,
        -0.07169904146250285, 0.047981702176079055, -0.11317649996515426, -0.0873801191019837, -0.08983665146835418,
        0.10593305123658658, 0.09049026703513974, -0.20309334744098434, -0.1268871622206159, 0.05129113627824605,
        0.06940244498440028, 0.0, 0.056094104534930904, -0.16307717161202426],
    'term stribeck_extra': [-0.16522506832183836, 0.11619844030974741, 0.02365866602170792, 0.1436397605107497,
        -0.14455998018701474, -0.0876577493328886, 0.13166913934290048, 0.1456757026945367, -0.1725433339710661,
        -0.1369144908365263, 0.11779329110581073, -0.17403045506804504, -0.12786030077144606, -0.13999548215748936,
        0.10881193407233555, 0.09448400960794112, -0.17498528245325284, -0.16011431714012347, 0.06510686823055643,
        0.060154972285452364, 0.0, 0.11730756444205732, -0.24800632247022902],
    'term temperature': [0.009002618278271313, 0.09747194682728628, 0.060598819061943546, 0.04577370301297536,
        0.017461953070989106, 0.13809716580808573, 0.13247944257417502, 0.1292332250546694, 0.12445949121778402,
        -0.07097176268731768, 0.029897021129702557, -0.23732730387461073, -0.007304078196215327, 0.0788122333121482,
        0.01786073430396376, -0.008206177542102525, -0.07084313024504352, -0.22189341024285242,
        -0.008596531548694442, 0.09782002376395027, 0.0, 0.13476397992790368, 0.022188802887193326],
    'term viscous_power': [-1.9449518672495758, 0.07399984468015436, 0.026437203937509996, 0.09364003500618016,
        -0.5270745428175849, -0.09177997740764525, 0.08261375712726443, 0.5400043517078493, -0.07346072118562524,
        -0.08082150168314263, 0.06779794214524668, -0.08739213830118463, -0.11879796367059525, -0.13093314516091498,
        0.10428076552191015, 0.08995284110965393, -0.6651343190892963, -0.650263355246614, 0.31018138654857813,
        0.3052294913386977, 0.0, 0.06730756444205732, -0.14800632247022902],
}


CASES = ([(f"law {law}", lambda law=law: law_model(law, seed=i)) for i, law in enumerate(LAWS)]
         + [(f"law {law} degraded", lambda law=law: law_model(law, seed=7, degraded=True))
            for law in LAWS if LAWS[law].optional]
         + [(f"term {kind}", lambda kind=kind: term_model(kind)) for kind in sorted(TERMS)])


def _pin_cases(n=12):
    """Print ``PINNED`` (run with the code to pin against)."""
    import textwrap

    print("PINNED = {")
    for name, make in CASES:
        m = make()
        vals = ", ".join(repr(float(x)) for x in m.evaluate(**inputs(m, n)))
        print(textwrap.fill(f"{name!r}: [{vals}],", 116, initial_indent="    ", subsequent_indent="        "))
    print("}")


def _reference(model, theta=None, v=None, *, load=None, temperature=None, t=None, acc=None, run=None):
    """evaluate as it was before it was made fast: per direction a mask, the base law on the
    selected samples, then each line through the registry's ``periodic`` term, then the terms."""
    v = np.atleast_1d(np.asarray(v, dtype=float))
    bc = lambda x: None if x is None else np.broadcast_to(np.asarray(x, dtype=float), v.shape)  # noqa: E731
    theta, load, temperature, t, acc = map(bc, (theta, load, temperature, t, acc))
    run = None if run is None else np.broadcast_to(np.asarray(run), v.shape)
    law = model.law_spec
    out, speed, sign = np.zeros(v.shape), np.abs(v), np.sign(v)
    for d, name in ((1.0, "positive"), (-1.0, "negative")):
        sel = sign == d
        if not sel.any():
            continue
        p = model.directions[name]
        ld = None if load is None else load[sel]
        mag = np.asarray(law.magnitude(speed[sel], ld, *[p.values[k] for k in law.params]), dtype=float)
        mag = np.broadcast_to(mag, (int(sel.sum()),)).copy()
        for h in p.harmonics:
            if h.amplitude is not None:
                mag += evaluate_term(h.term(), theta=theta[sel], v=v[sel], load=ld)[0]
        out[sel] = d * mag
    for term in model.terms:
        contrib, signed = evaluate_term(term, theta=theta, v=v, load=load, temperature=temperature, t=t, acc=acc,
                                        run=run)
        out += contrib if signed else sign * contrib
    return out


def _close(got, want):
    """Largest difference relative to the tolerance (<= 1 passes).  The same operations in the same
    order; only numpy's vectorised and scalar exp/sin paths may differ, by <= 1 ulp each, so the
    error is a few eps of the parts summed: 1e-12 relative, with a floor of 1e-14 of the largest
    value (~45 eps) where parts cancel near a zero crossing.  A changed formula, a line left out or a
    sample given the other direction's parameters is off by far more (>= 1e-6 relative)."""
    tol = 1e-12 * np.abs(want) + 1e-14 * np.max(np.abs(want))
    return float(np.max(np.abs(got - want) / tol))


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_evaluate_returns_the_values_pinned_before_the_change(name):
    m = dict(CASES)[name]()
    got = m.evaluate(**inputs(m, 12))
    assert got.shape == (len(PINNED[name]),)
    assert _close(got, np.array(PINNED[name])) <= 1.0


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_evaluate_matches_the_per_line_algorithm_on_many_points(name):
    m = dict(CASES)[name]()
    x = inputs(m, 3000, seed=2)
    assert _close(m.evaluate(**x), _reference(m, **x)) <= 1.0


def _silo4_fitted():
    """The SILO4 joint fit of gearspec 0.4.1 (lines with speed ranges, const and exp laws; negative
    Stribeck part not identified)."""
    import json
    from pathlib import Path

    d = json.loads((Path(__file__).parent / "data" / "models_0.4.1.json").read_text())
    return FrictionModel.from_dict(d["models"]["silo4 joint fit, harmonics with speed_range"]["model"])


@pytest.mark.parametrize("make", [_silo4_fitted, lambda: law_model("silo4", seed=11)], ids=["fitted", "silo4"])
def test_long_inputs_in_blocks_and_short_ones_both_ways(make):
    # 100003 samples: several blocks, each moving both ways, with runs of one direction in between
    # (the block fast path); then every short length up to 40 (both directions at once)
    m = make()
    x = inputs(m, 100_000, seed=4)
    x["v"][20_000:50_000] = np.abs(x["v"][20_000:50_000])
    x["v"][60_000:65_000] = -np.abs(x["v"][60_000:65_000])
    assert _close(m.evaluate(**x), _reference(m, **x)) <= 1.0
    for n in range(1, 41):
        y = {k: a[:n] for k, a in inputs(m, n, seed=n).items()}
        assert _close(m.evaluate(**y), _reference(m, **y)) <= 1.0, n


def test_scalars_and_arrays_of_any_shape_as_before():
    m = law_model("silo4", seed=2)
    assert m.evaluate(0.3, -2.0).shape == (1,)
    assert m.evaluate(0.3, -2.0)[0] == _reference(m, 0.3, -2.0)[0]
    th, v = np.linspace(0, 9, 12).reshape(3, 4), np.linspace(-5, 6, 12).reshape(3, 4)
    got = m.evaluate(th, v)
    assert got.shape == (3, 4) and _close(got.ravel(), _reference(m, th.ravel(), v.ravel())) <= 1.0
    # infinite and NaN velocities give what they gave (NaN: no direction, 0; inf: the laws' limits)
    v = np.array([np.inf, -np.inf, np.nan, 0.0, 3.0])
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(m.evaluate(np.ones(5), v), _reference(m, np.ones(5), v))


def _write_paths():
    """Every way the engines change a model after it was evaluated (``git grep`` of gearspec 0.5):
    ``Direction.set``, a harmonic's attributes, a speed range changed in place, the list of
    harmonics, ``model.law``, a direction replaced, ``not_identified``."""
    def set_(m):
        m.params("positive").set("tau_c", 0.5, 0.01)

    def attr(m):
        m.harmonics("negative")[0].decay = 0.3

    def law_attr(m):
        m.harmonics("positive")[0].law = "power"

    def in_place(m):
        m.harmonics("positive")[2].speed_range[1] = 5.0

    def append(m):
        m.harmonics("negative").append(Harmonic(0.9, 0.04, 0.01, 0.2))

    def clear(m):
        m.params("positive").harmonics = []

    def law(m):
        m.law = "coulomb_viscous"

    def replace(m):
        m.directions["negative"] = m.directions["positive"]

    def value_dict(m):
        m.params("negative").values["viscous"] = 0.01

    return [set_, attr, law_attr, in_place, append, clear, law, replace, value_dict]


@pytest.mark.parametrize("change", _write_paths(), ids=lambda f: f.__name__)
def test_a_model_changed_after_evaluation_evaluates_its_new_values(change):
    m = law_model("silo4", seed=5)
    x = inputs(m, 500, seed=6)
    before = m.evaluate(**x)
    change(m)
    fresh = FrictionModel.from_dict(m.to_dict())        # a new model: nothing cached
    after = m.evaluate(**x)
    np.testing.assert_array_equal(after, fresh.evaluate(**x))
    assert np.max(np.abs(after - before)) > 1e-4          # the change shows (torques ~0.1 Nm)


def test_the_compiled_form_is_reused_until_a_value_changes_and_not_pickled():
    import pickle

    m = law_model("silo4", seed=5)
    m.evaluate(0.1, 1.0)
    c = m._compiled()
    m.evaluate(0.2, -1.0)
    assert m._compiled() is c
    m.params("positive").se["tau_c"] = 1.0               # a standard error: not part of evaluation
    assert m._compiled() is c
    m.params("positive").set("tau_c", 0.2)
    assert m._compiled() is not c
    assert "_compiled_cache" not in pickle.loads(pickle.dumps(m)).__dict__


def test_errors_name_what_is_missing_as_before():
    m = law_model("silo4", seed=7, degraded=True)
    m.params("negative").set("tau_c", None)
    m.not_identified["negative.tau_c"] = "no negative plateaus"
    assert np.isfinite(m.evaluate(0.0, [1.0, 2.0])).all()     # the positive direction only: fine
    with pytest.raises(InputError, match="no negative-direction value for tau_c .not identified: no negative plateaus"):
        m.evaluate(0.0, [1.0, -2.0])
    with pytest.raises(InputError, match="position-locked harmonics and needs theta"):
        law_model("silo4").evaluate(None, [1.0])
    assert law_model("silo4").evaluate(None, [0.0])[0] == 0.0    # at rest no line is evaluated
    with pytest.raises(InputError, match="load coefficient .SILO4 eq. 14. needs the 'load' channel"):
        FrictionModel("coulomb_viscous", {"tau_c": 0.1, "viscous": 0.0, "harmonics": [
            {"frequency": 1.0, "amplitude": 0.01, "load_coefficient": 1e-3}]}).evaluate(0.0, [1.0])
    bad = FrictionModel("coulomb_viscous", {"tau_c": 0.1, "viscous": 0.0, "harmonics": [
        {"frequency": 1.0, "amplitude": 0.01, "law": "cubic"}]})
    with pytest.raises(InputError, match="unknown amplitude law 'cubic'"):
        bad.evaluate(0.0, [1.0])


def test_an_evaluator_computes_what_evaluate_does_with_the_parameters_it_was_taken_with():
    m = law_model("silo4", seed=8).with_terms({"kind": "temperature", "coefficient": 1e-3, "reference": 20.0})
    x = inputs(m, 300, seed=9)
    f = m.evaluator()
    before = m.evaluate(**x)
    np.testing.assert_array_equal(f(**x), before)
    m.params("positive").set("tau_c", 0.9)
    assert np.max(np.abs(m.evaluate(**x) - before)) > 0.5      # the model sees its change
    np.testing.assert_array_equal(f(**x), before)                # the evaluator, as documented, does not


# ------------------------------------------------------------------ threads (gearspec 0.6)
def _spy_blocks(monkeypatch, delay=0.0):
    """Record, for every block evaluated, the thread that evaluated it and numpy's error state there;
    ``delay`` (s) per block, so that a helper thread surely takes some blocks of a short input."""
    import threading
    import time

    from gearspec.terms.lines import CompiledFriction

    seen = []
    original = CompiledFriction._slice

    def spy(self, *args):
        seen.append((threading.get_ident(), np.geterr()["invalid"]))
        if delay:
            time.sleep(delay)
        return original(self, *args)

    monkeypatch.setattr(CompiledFriction, "_slice", spy)
    return seen


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_blocks_on_threads_give_the_single_call_values_bit_for_bit(name, monkeypatch):
    # Known answer: the values of one call on one thread with the default blocks (20003 samples: one or
    # two blocks).  The same inputs cut into blocks of 97 samples (206 blocks, most moving both ways,
    # some one way after the runs forced below) and shared among 2 and 3 threads must give every
    # value bit for bit: each sample's arithmetic does not depend on its block or thread.
    import gearspec.terms.lines as lines

    want_model = dict(CASES)[name]()
    x = inputs(want_model, 20_000, seed=12)
    x["v"][3000:3500] = np.abs(x["v"][3000:3500])
    x["v"][9000:9300] = -np.abs(x["v"][9000:9300])
    want = want_model.evaluate(**x, threads=1)
    monkeypatch.setattr(lines, "PARALLEL_MIN_SAMPLES", 0)
    seen = _spy_blocks(monkeypatch)
    for threads in (2, 3):
        m = dict(CASES)[name]()
        m._compiled().block = 97
        got = m.evaluate(**x, threads=threads)
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)
        assert not np.shares_memory(got, x["v"])
    assert len(seen) == 2 * math.ceil(len(x["v"]) / 97)


def test_long_inputs_use_the_threads_and_short_ones_only_the_calling_thread(monkeypatch):
    # The rule: threads only from PARALLEL_MIN_SAMPLES samples (below it the pool's hand-over is not
    # small against the work).  Blocks are recorded with the thread that ran them (1 ms each, so the
    # helper thread takes some of the long input's 6 blocks).
    import threading

    from gearspec.terms.lines import PARALLEL_MIN_SAMPLES

    m = law_model("silo4", seed=13)
    seen = _spy_blocks(monkeypatch, delay=0.001)
    short = inputs(m, PARALLEL_MIN_SAMPLES - 100, seed=14)
    m.evaluate(short["theta"], short["v"], threads=2)
    assert len(seen) > 1 and {t for t, _ in seen} == {threading.get_ident()}
    seen.clear()
    long = inputs(m, PARALLEL_MIN_SAMPLES, seed=14)
    m.evaluate(long["theta"], long["v"], threads=2)
    assert len({t for t, _ in seen}) == 2
    seen.clear()
    m.evaluate(long["theta"], long["v"], threads=1)
    assert {t for t, _ in seen} == {threading.get_ident()}


def test_helper_threads_run_under_the_callers_numpy_error_state(monkeypatch):
    # np.errstate is a context variable: a thread of the pool starts with numpy's default ("warn").
    # Each helper runs in a copy of the caller's context, so a caller's errstate("ignore") holds in
    # every block (infinite speeds make inf - inf in the Stribeck part: a warning otherwise).
    import gearspec.terms.lines as lines

    monkeypatch.setattr(lines, "PARALLEL_MIN_SAMPLES", 0)
    seen = _spy_blocks(monkeypatch, delay=0.001)
    m = law_model("silo4", seed=2)
    m._compiled().block = 50
    v = np.tile([np.inf, -np.inf, 3.0, np.nan], 500)
    with np.errstate(invalid="ignore"):
        got = m.evaluate(np.ones(len(v)), v, threads=2)
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(got, m.evaluate(np.ones(len(v)), v, threads=1))
    assert len({t for t, _ in seen}) == 2
    assert {e for _, e in seen} == {"ignore"}


def test_the_number_of_threads_default_environment_and_refusals(monkeypatch):
    import os

    from gearspec.terms.lines import MAX_THREADS, THREADS_ENV, default_threads

    monkeypatch.delenv(THREADS_ENV, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(16)), raising=False)
    assert default_threads() == MAX_THREADS == 4           # 16 CPUs: capped
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert default_threads() == 1                          # one CPU allowed: one thread
    monkeypatch.setenv(THREADS_ENV, "3")
    assert default_threads() == 3                          # the environment wins over the CPUs
    m = law_model("silo4", seed=2)
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(InputError, match="GEARSPEC_THREADS must be a whole number of threads >= 1"):
            default_threads()
    with pytest.raises(InputError, match="GEARSPEC_THREADS"):
        m.evaluator()                                      # the default is resolved when asked for
    assert m.evaluate(0.3, 1.0).shape == (1,)             # a short input never looks the default up
    for bad in (0, 1.5, "2", True):
        with pytest.raises(InputError, match="threads must be a whole number >= 1"):
            m.evaluate(0.3, 1.0, threads=bad)


def test_a_call_does_not_wait_for_a_pool_thread_busy_elsewhere(monkeypatch):
    # The pool's one thread is held by another task (another caller's work); evaluate's calling
    # thread takes every block itself and returns, not waiting for a helper that never started.
    import threading

    import gearspec.terms.lines as lines

    m = law_model("silo4", seed=13)
    x = inputs(m, lines.PARALLEL_MIN_SAMPLES, seed=15)
    want = m.evaluate(x["theta"], x["v"], threads=1)
    release = threading.Event()
    busy = lines._shared_pool(1).submit(release.wait, 60)
    got = []
    caller = threading.Thread(target=lambda: got.append(m.evaluate(x["theta"], x["v"], threads=2)))
    caller.start()
    caller.join(30)                 # ~0.1 s of work; 30 s: only a call waiting for the busy thread takes it
    finished = not caller.is_alive()
    release.set()
    busy.result()
    caller.join()
    assert finished
    np.testing.assert_array_equal(got[0], want)


def test_a_forked_child_gets_its_own_pool(monkeypatch):
    # After fork the parent's pool threads do not exist in the child: the child must start its own
    # pool (its blocks on 2 threads, as in the parent), not hand blocks to threads that never run.
    import multiprocessing as mp

    m = law_model("silo4", seed=13)
    x = inputs(m, 1 << 17, seed=16)
    m.evaluate(x["theta"], x["v"], threads=2)            # the parent's pool exists
    seen = _spy_blocks(monkeypatch, delay=0.001)

    def child(conn):
        seen.clear()
        out = m.evaluate(x["theta"], x["v"], threads=2)
        conn.send((len({t for t, _ in seen}), bool(np.array_equal(out, m.evaluate(x["theta"], x["v"], threads=1)))))

    ctx = mp.get_context("fork")
    a, b = ctx.Pipe()
    p = ctx.Process(target=child, args=(b,))
    p.start()
    ready = a.poll(120)
    p.join(5)
    if p.is_alive():
        p.kill()
    assert ready and a.recv() == (2, True)
