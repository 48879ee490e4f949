"""SSP import: our export read back runs bit for bit; a hand-written SSP (libcosim/Ecos style)
runs as its closed-form solution says; unsupported SSP content is refused in one line naming
the element; ``drillcosim ssp`` and ``drillcosim run X.ssp`` from the command line.

The hand-written system: a sine source ``y = A sin(w t)`` feeding a static gain ``y = -k u``
feeding an integrator ``x' = u``, in Jacobi fashion with a zero-order hold. The integrator's
input over step n (n >= 1) is the gain's output read after step n-1, i.e. ``-k A sin(w t_(n-1))``
(0 for n = 0: every start value is 0 and sin 0 = 0), so

    x_N = x0 - k A H sum_{m=0}^{N-2} sin(w m H).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from drillcosim.cosim.cli import main
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.ssp import export_ssp
from drillcosim.cosim.master.ssp_import import SspError, read_ssp
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
from support.required import import_module

A, W, K, X0, H, STOP = 2.0, 5.0, 3.0, 0.25, 0.01, 1.0

# libcosim / Ecos style: ssd/ssc/ssv/osp prefixes, FMUs under resources/, a parameter set
# in an SSV file and one inline, connector units, geometry, OSP base step in the experiment
HAND_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"
    name="SourceGainIntegrator" version="1.0">
  <ssd:System name="SourceGainIntegrator" description="written by hand">
    <ssd:Elements>
      <ssd:Component name="source" source="resources/mt_source.fmu">
        <ssd:Connectors>
          <ssd:Connector name="y" kind="output"><ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="amplitude" kind="parameter"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="omega" kind="parameter"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="ssv/source.ssv"/>
        </ssd:ParameterBindings>
        <ssd:ElementGeometry x1="0" y1="0" x2="10" y2="10"/>
      </ssd:Component>
      <ssd:Component name="gain" source="resources/mt_gain.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="initialValues">
                <ssv:Parameters>
                  <ssv:Parameter name="k"><ssv:Real value="{k}"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="integrator" source="resources/mt_integrator.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="x" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="ssv/integrator.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="source" startConnector="y" endElement="gain" endConnector="u"/>
      <ssd:Connection startElement="gain" startConnector="y" endElement="integrator"
                      endConnector="u"><ssd:ConnectionGeometry pointsX="1" pointsY="2"/>
      </ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}">
    <ssd:Annotations>
      <ssc:Annotation type="com.opensimulationplatform">
        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="{h}"/></osp:Algorithm>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""

SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="initialValues">
  <ssv:Parameters>
{params}
  </ssv:Parameters>
</ssv:ParameterSet>
"""


def _ssv(**params: float) -> str:
    rows = "\n".join(f'    <ssv:Parameter name="{n}"><ssv:Real value="{v!r}"/></ssv:Parameter>'
                     for n, v in params.items())
    return SSV.format(params=rows)


def make_ssp(path: Path, fmus: dict[str, Path], ssd: str | None = None,
             extra: dict[str, str] | None = None) -> Path:
    """A hand-written SSP archive (the default SSD: source -> gain -> integrator)."""
    files = {"ssv/source.ssv": _ssv(amplitude=A, omega=W),
             "ssv/integrator.ssv": _ssv(x0=X0), **(extra or {})}
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd or HAND_SSD.format(k=K, stop=STOP, h=H))
        for name, text in files.items():
            zf.writestr(name, text)
        for name in ("mt_source", "mt_gain", "mt_integrator"):
            zf.write(fmus[name], f"resources/{name}.fmu")
    return path


def closed_form(n_rows: int) -> np.ndarray:
    """x at t = 0, H, ..., (n_rows - 1) H (module docstring)."""
    inputs = np.concatenate([[0.0], -K * A * np.sin(W * H * np.arange(n_rows - 2))])
    return X0 + H * np.concatenate([[0.0], np.cumsum(inputs)])


# ------------------------------------------------------------------- round trip
@pytest.fixture(scope="module")
def multirate(project_fmus):
    """Controller every 2 base steps, Integer/Boolean/String/Real start values."""
    config = load_config("paper_restricted_actuator", {
        "controller.gain": 5e8, "cosim.step": 1e-3, "cosim.controller_sample_period": 2e-3,
        "cosim.stop_time": 0.2, "cosim.algorithm": "jacobi", "cosim.order": ["plant", "controller"]})
    return build_system(config, "fmu", fmu_dir=project_fmus["DrillstringPlant"].parent)


def test_round_trip_export_import_is_bit_for_bit(multirate, tmp_path) -> None:
    exp = export_ssp(multirate.system, tmp_path / "rt.ssp")
    with read_ssp(exp.path) as imp:
        a, b = multirate.system, imp.system
        assert imp.notes == ()
        assert (b.base_step, b.start_time, b.stop_time, b.algorithm) == \
            (a.base_step, a.start_time, a.stop_time, "jacobi")
        for fa, fb in zip(a.fmus, b.fmus, strict=True):
            assert (fa.name, fa.parameters, fa.sample_period_ticks) == \
                (fb.name, fb.parameters, fb.sample_period_ticks)
            assert {k: type(v) for k, v in fa.parameters.items()} == \
                {k: type(v) for k, v in fb.parameters.items()}
            assert Path(fb.path).read_bytes() == Path(fa.path).read_bytes()
        assert set(b.connections) == set(a.connections) and len(b.connections) == 8
        ours = Master(a).simulate(0.2, imp.outputs).data
        back = Master(b).simulate(0.2, imp.outputs).data
        directory = imp.directory
    assert not directory.exists()  # the extracted files are gone
    assert len(imp.outputs) == 27 and len(ours) == 201
    for name in ours.dtype.names:
        assert np.array_equal(ours[name], back[name]), name
    assert np.max(np.abs(ours["controller.actuator1_force_C"])) > 0


def test_cli_writes_a_scene_ssp_and_runs_it_bit_for_bit(project_fmus, tmp_path, capsys) -> None:
    fmu_dir = str(project_fmus["DrillstringPlant"].parent)
    ssp = tmp_path / "loop.ssp"
    assert main(["ssp", "paper_closed_loop", "--out", str(ssp), "--fmu-dir", fmu_dir]) == 2
    assert "cannot hold algorithm 'gauss_seidel'" in capsys.readouterr().err
    assert main(["ssp", "paper_closed_loop", "--out", str(ssp), "--fmu-dir", fmu_dir,
                 "--set", "cosim.algorithm='jacobi'", "--step", "1e-4",
                 "--stop-time", "0.05"]) == 0
    assert f"wrote {ssp}" in capsys.readouterr().out
    out = tmp_path / "run"
    assert main(["run", str(ssp), "--out", str(out), "--no-progress"]) == 0
    rows = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["end_time_s"] == pytest.approx(0.05) and summary["step_s"] == 1e-4
    assert summary["components"]["controller"]["start_values"]["gain"] == 1e9
    with read_ssp(ssp) as imp:
        ref = Master(imp.system).simulate(0.05, imp.outputs).data
    assert header == ["time", *imp.outputs] and rows.shape == (501, len(header))
    for j, name in enumerate(header):
        assert np.array_equal(rows[:, j], ref[name]), name  # %.17g: exact
    # an SSP takes no scene options
    assert main(["run", str(ssp), "--gain", "1"]) == 2
    assert "takes --step, --stop-time and --out, not --gain" in capsys.readouterr().err


# ------------------------------------------------------------- hand-written SSP
def test_hand_written_ssp_runs_as_its_closed_form(fmus, tmp_path) -> None:
    ssp = make_ssp(tmp_path / "hand.ssp", fmus)
    with read_ssp(ssp) as imp:
        spec = imp.system
        assert spec.base_step == H and spec.stop_time == STOP
        assert spec.fmu("source").parameters == {"amplitude": A, "omega": W}
        assert spec.fmu("gain").parameters == {"k": K}
        assert spec.fmu("integrator").parameters == {"x0": X0}
        data = Master(spec).simulate(STOP, imp.outputs).data
    x = data["integrator.x"]
    assert len(x) == 101
    np.testing.assert_allclose(x, closed_form(len(x)), rtol=0, atol=1e-13)
    assert np.ptp(x) > 0.1  # the loop moved


def test_hand_written_ssp_unpacked_folder_and_step_override(fmus, tmp_path) -> None:
    ssp = make_ssp(tmp_path / "hand.ssp", fmus)
    folder = tmp_path / "unpacked"
    with zipfile.ZipFile(ssp) as zf:
        zf.extractall(folder)
    with read_ssp(folder, step=H / 2, stop_time=0.5) as imp:
        assert imp.directory is None and imp.system.base_step == H / 2
        assert imp.system.stop_time == 0.5
        assert Path(imp.system.fmu("gain").path).parent == folder / "resources"
    assert (folder / "resources" / "mt_gain.fmu").is_file()  # an unpacked SSP is left alone
    with read_ssp(folder / "SystemStructure.ssd") as imp:
        assert imp.system.base_step == H


def test_system_level_bindings_with_prefix_override_component_ones(fmus, tmp_path) -> None:
    ssd = HAND_SSD.format(k=K, stop=STOP, h=H).replace("""    <ssd:Connections>""", """
    <ssd:ParameterBindings>
      <ssd:ParameterBinding prefix="gain.">
        <ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="override">
            <ssv:Parameters>
              <ssv:Parameter name="k"><ssv:Integer value="7"/></ssv:Parameter>
              <ssv:Parameter name="no_such_variable"><ssv:Real value="1"/></ssv:Parameter>
            </ssv:Parameters>
          </ssv:ParameterSet>
        </ssd:ParameterValues>
      </ssd:ParameterBinding>
    </ssd:ParameterBindings>
    <ssd:Connections>""")
    with read_ssp(make_ssp(tmp_path / "sys.ssp", fmus, ssd)) as imp:
        assert imp.system.fmu("gain").parameters == {"k": 7.0}  # system over component
        assert isinstance(imp.system.fmu("gain").parameters["k"], float)  # Real variable
        assert len(imp.notes) == 1 and "'no_such_variable'" in imp.notes[0] \
            and "ignored" in imp.notes[0]


def _broken(old: str, new: str) -> str:
    ssd = HAND_SSD.format(k=K, stop=STOP, h=H)
    assert old in ssd, old
    return ssd.replace(old, new, 1)


GAIN_Y = ('<ssd:Connection startElement="gain" startConnector="y" endElement="integrator"\n'
          '                      endConnector="u">')
ELEMENTS = "    <ssd:Elements>\n"


@pytest.mark.parametrize(("old", "new", "message"), [
    (ELEMENTS, ELEMENTS + '<ssd:System name="inner"/>',
     r"<ssd:System> in <ssd:System name='SourceGainIntegrator'>: nested systems are not"),
    (ELEMENTS, '<ssd:SignalDictionaries><ssd:SignalDictionary name="d"/>'
               '</ssd:SignalDictionaries>\n' + ELEMENTS,
     r"<ssd:SignalDictionaries> in .*: signal dictionaries are not supported"),
    ('<ssd:Component name="gain" source="resources/mt_gain.fmu">',
     '<ssd:Component name="gain" source="resources/sub.ssd" type="application/x-ssp-definition">',
     r"<ssd:Component name='gain'>: type 'application/x-ssp-definition': nested systems"),
    (GAIN_Y, GAIN_Y + '<ssc:LinearTransformation factor="2" offset="0"/>',
     r"<ssc:LinearTransformation> in <ssd:Connection gain.y -> integrator.u>: connection "
     r"transformations are not supported"),
    ('<ssd:Connector name="u" kind="input"><ssc:Real unit="m"/>',
     '<ssd:Connector name="u" kind="input"><ssc:Real unit="mm"/>',
     r"<ssd:Connection source.y -> gain.u>: units differ \('m' -> 'mm'\): unit conversions"),
    ('<ssd:ParameterBinding source="ssv/integrator.ssv"/>',
     '<ssd:ParameterBinding source="ssv/integrator.ssv"><ssd:ParameterMapping/>'
     '</ssd:ParameterBinding>', r"<ssd:ParameterMapping> in .*: parameter mappings"),
    ('<ssv:Real value="3.0"/>', '<ssv:Enumeration value="high"/>',
     r"<ssv:Enumeration> in .*: Enumeration parameter values are not supported"),
    ('<osp:FixedStepAlgorithm baseStepSize="0.01"/>', "",
     r"no step size .*: give one \(--step H\)"),
    ('version="1.0">', 'version="2.0">', r"version '2.0': only SSP 1.0 is supported"),
    ('startElement="source" startConnector="y"', 'startConnector="y"',
     r"<ssd:Connection \(system\).y -> gain.u>: connects a connector of the system itself"),
    ('startElement="source" startConnector="y" endElement="gain" endConnector="u"',
     'startElement="gain" startConnector="u" endElement="source" endConnector="y"',
     r"the start connector is of kind 'input', must be 'output'"),
    ('</ssd:Elements>', '</ssd:Elements><ssd:Connectors><ssd:Connector name="p" '
     'kind="input"/></ssd:Connectors>', r"connectors of the system itself are not supported"),
    ('<ssd:Component name="integrator" source="resources/mt_integrator.fmu">',
     '<ssd:Component name="integrator" source="resources/mt_integrator.fmu" '
     'implementation="ModelExchange">', r"implementation 'ModelExchange'"),
    ('<ssd:Component name="integrator" source="resources/mt_integrator.fmu">',
     '<ssd:Component name="integrator" source="../mt_integrator.fmu">',
     r"must stay inside the package"),
    (ELEMENTS, ELEMENTS + "<ssd:Whatever/>",
     r"<ssd:Whatever> in .*: not an SSP 1.0 element this importer supports"),
])
def test_unsupported_content_is_refused_in_one_line_naming_the_element(
        fmus, tmp_path, old, new, message) -> None:
    ssp = make_ssp(tmp_path / "bad.ssp", fmus, _broken(old, new))
    with pytest.raises(SspError, match=message) as info:
        read_ssp(ssp)
    assert "\n" not in str(info.value) and str(info.value).startswith("bad.ssp: ")


def test_a_step_size_hint_must_be_a_multiple_of_the_base_step(fmus, tmp_path) -> None:
    ssd = _broken('<ssd:Component name="gain" source="resources/mt_gain.fmu">',
                  '<ssd:Component name="gain" source="resources/mt_gain.fmu"><ssd:Annotations>'
                  '<ssc:Annotation type="com.opensimulationplatform"><osp:StepSizeHint '
                  'value="0.025"/></ssc:Annotation></ssd:Annotations>')
    with pytest.raises(SspError, match=r"osp:StepSizeHint value=0.025: not a positive integer "
                                       r"multiple of the base step 0.01"):
        read_ssp(make_ssp(tmp_path / "hint.ssp", fmus, ssd))
    with read_ssp(make_ssp(tmp_path / "hint2.ssp", fmus, ssd.replace('"0.025"', '"0.03"'))) \
            as imp:
        assert imp.system.fmu("gain").sample_period_ticks == 3


def test_refusals_leave_no_extracted_files(fmus, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    with pytest.raises(SspError):
        read_ssp(make_ssp(tmp_path / "bad.ssp", fmus, _broken('version="1.0">',
                                                              'version="2.0">')))
    assert list((tmp_path / "tmp").iterdir()) == []


def test_cli_refuses_a_bad_ssp_with_exit_2_in_one_line(fmus, tmp_path, capsys) -> None:
    ssp = make_ssp(tmp_path / "bad.ssp", fmus, _broken(ELEMENTS, ELEMENTS + "<ssd:System/>"))
    assert main(["run", str(ssp), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("drillcosim run: error: bad.ssp: <ssd:System>") and "\n" not in err
    no_step = make_ssp(tmp_path / "nostep.ssp", fmus,
                       _broken('<osp:FixedStepAlgorithm baseStepSize="0.01"/>', ""))
    assert main(["run", str(no_step), "--out", str(tmp_path / "out")]) == 2
    assert "give one (--step H)" in capsys.readouterr().err
    assert main(["run", str(no_step), "--step", "0.01", "--out", str(tmp_path / "out"),
                 "--no-progress"]) == 0
    x = np.loadtxt(tmp_path / "out" / "results.csv", delimiter=",", skiprows=1)
    header = (tmp_path / "out" / "results.csv").read_text().splitlines()[0].split(",")
    np.testing.assert_allclose(x[:, header.index("integrator.x")], closed_form(len(x)),
                               rtol=0, atol=1e-13)


@pytest.mark.interop
def test_libcosim_runs_the_hand_written_ssp_like_our_import(fmus, tmp_path) -> None:
    import_module("libcosimpy")
    from support.engines import compare, run_libcosim

    ssp = make_ssp(tmp_path / "hand.ssp", fmus)
    with read_ssp(ssp) as imp:
        ours = Master(imp.system).simulate(STOP, imp.outputs).data
        outputs = imp.outputs
    rows = run_libcosim(ssp, H, round(STOP / H), outputs, tmp_path)
    result = compare(ours[1:], {o: rows[:, j] for j, o in enumerate(outputs)}, rtol=1e-12)
    assert result.peak["integrator.x"] > 0.1
