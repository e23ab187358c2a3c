"""What ``gearspec spectrum`` no longer pays for, with the same numbers: nifty-ls imported without
its astropy hook (also from threads at once), a peak's dict without a deep copy of every number.
(The loader's integer run ids: tests/test_spectrum_scale.py.)"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_nifty_periodogram_without_astropy_same_power():
    """The nifty periodogram leaves astropy unimported (0.45 s and 35 MB per process) and gives the
    same power, bit for bit, as nifty-ls imported the usual way (astropy's hook in place); astropy's
    own method still works afterwards."""
    out = _run("""
        import sys
        import numpy as np
        from gearspec.spectrum.periodogram import LombScargle
        rng = np.random.default_rng(3)
        th = np.sort(rng.uniform(0, 40, 3000)); y = np.sin(2 * np.pi * 1.7 * th) + 0.3 * rng.normal(size=3000)
        p = LombScargle(th, y, method="nifty").power_grid(0.05, 0.0125, 4000)
        print(any(k == "astropy" or k.startswith("astropy.") for k in sys.modules))
        print(float(p.sum()).hex(), int(p.argmax()))
        pa = LombScargle(th, y, method="astropy").power(0.05 + 0.0125 * np.arange(0, 4000, 50))
        print(float(np.max(np.abs(pa - p[::50])) / p.max()) < 1e-6)
    """).splitlines()
    ref = _run("""
        import numpy as np
        import astropy.timeseries.periodograms.lombscargle.implementations.main  # the hook nifty-ls registers into
        import nifty_ls
        rng = np.random.default_rng(3)
        th = np.sort(rng.uniform(0, 40, 3000)); y = np.sin(2 * np.pi * 1.7 * th) + 0.3 * rng.normal(size=3000)
        p = np.asarray(nifty_ls.lombscargle(th, y, fmin=0.05, fmax=0.05 + 0.0125 * 3999, Nf=4000, normalization="psd",
                                            backend="finufft", assume_sorted_t=True, finufft_kwargs={"eps": 1e-7}).power)
        print(float(p.sum()).hex(), int(p.argmax()))
    """)
    assert out[0] == "False"              # astropy never imported by the nifty periodogram
    assert out[1] == ref                  # the same power (its sum to the last bit, and its peak)
    assert int(ref.split()[1]) == round((1.7 - 0.05) / 0.0125)  # at the line's frequency
    assert out[2] == "True"               # astropy's method imports and agrees afterwards


def test_peak_to_dict_is_asdict():
    """A peak's dict is :func:`dataclasses.asdict`'s, key for key and type for type, with its
    ``aliased_from`` a copy (the table a report builds must not alias the result's peaks)."""
    from dataclasses import asdict

    from gearspec.spectrum.results import Peak

    src = {"label": "motor shaft", "frequency": 0.159, "order": 1.0}
    p = Peak(frequency=np.float64(2.5), amplitude=1e-4, amplitude_se=2e-6, phase=0.3, phase_se=0.01, fap=1e-9,
             order=None, label="alias of motor shaft", declared=False, snr=np.float32(40.0), aliased_from=src,
             quantisation_harmonic=2)
    d, ref = p.to_dict(), asdict(p)
    assert d == ref and list(d) == list(ref)
    assert [type(v) for v in d.values()] == [type(v) for v in ref.values()]
    assert d["aliased_from"] == src and d["aliased_from"] is not src
    d["aliased_from"]["frequency"] = 0.0
    assert p.aliased_from["frequency"] == 0.159


def test_nifty_periodogram_first_called_from_threads_at_once():
    """Segments run in threads, and the first periodograms import nifty-ls: every thread gets the
    module imported completely (a half-initialised module has no ``lombscargle`` yet) and the same
    power as one call alone.  Eight threads released together, in three fresh processes."""
    code = """
        import threading
        import numpy as np
        from gearspec.spectrum.periodogram import LombScargle
        th = np.linspace(0, 30, 2000); y = np.sin(2 * np.pi * 2.0 * th)
        bar, out, err = threading.Barrier(8), [], []
        def one():
            bar.wait()
            try:
                out.append(float(LombScargle(th, y, method="nifty", nthreads=1).power_grid(0.1, 0.02, 500).sum()))
            except Exception as exc:
                err.append(repr(exc))
        ts = [threading.Thread(target=one) for _ in range(8)]
        [t.start() for t in ts]; [t.join() for t in ts]
        alone = float(LombScargle(th, y, method="nifty", nthreads=1).power_grid(0.1, 0.02, 500).sum())
        print(len(err), len(out), len(set(out)), out[0] == alone if out else None)
    """
    for _ in range(3):
        assert _run(code) == "0 8 1 True"
