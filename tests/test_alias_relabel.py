
from gearspec.segment.segmentation import Segment
from gearspec.spectrum.pipeline import relabel_aliases
from gearspec.spectrum.results import Peak, SegmentSpectrum


def _peak(f, **kw):
    return Peak(frequency=f, amplitude=1e-3, amplitude_se=1e-5, phase=0.0, phase_se=0.01, fap=1e-8, order=None,
                label=None, declared=False, snr=100.0, **kw)


def _segments(encoder_line: bool):
    # slow segment B measures a line at 130 cycles/rad (Nyquist 500); fast segment A samples every
    # 0.01 rad (Nyquist 50), where 130 folds to |130 - 100| = 30 cycles/rad
    b = SegmentSpectrum(Segment(0, 0, 10001, 1, 1.0), [_peak(130.0, quantisation_harmonic=1 if encoder_line else None)],
                        0.01, 1e-4, 10.0, 500.0, 0, [], None)
    a = SegmentSpectrum(Segment(1, 0, 1001, 1, 10.0), [_peak(30.0)], 0.01, 1e-4, 10.0, 50.0, 0, [], None)
    return [b, a]


def test_a_peak_at_the_alias_of_a_line_measured_elsewhere_is_labelled_but_not_of_an_encoder_line():
    segs = _segments(encoder_line=False)
    assert relabel_aliases(segs) == 1 and segs[1].peaks[0].label.startswith("alias of")
    # the encoder's count-rate line moves with the speed: it is no position-locked line that another
    # segment could alias, so the fast segment's peak stays unexplained
    segs = _segments(encoder_line=True)
    assert relabel_aliases(segs) == 0 and segs[1].peaks[0].label is None
