"""The launch file: compiles, starts only installed console scripts, is installed."""

import ast
import pathlib

from test_dependencies import setup_kwargs

REPO = pathlib.Path(__file__).resolve().parents[1]
LAUNCH = REPO / 'launch' / 'rwa_monitor.launch.py'


def _console_scripts():
    scripts = setup_kwargs('bdist_wheel')['entry_points']['console_scripts']
    return {entry.split('=')[0].strip() for entry in scripts}


def test_launch_file_compiles_and_names_installed_executables():
    source = LAUNCH.read_text()
    tree = ast.parse(source)
    compile(source, str(LAUNCH), 'exec')
    executables = [kw.value.value for node in ast.walk(tree) if isinstance(node, ast.Call)
                   for kw in node.keywords if kw.arg == 'executable']
    assert executables and set(executables) <= _console_scripts()
    names = [kw.value.value for node in ast.walk(tree) if isinstance(node, ast.Call)
             for kw in node.keywords if kw.arg == 'name']
    assert {'telemetry_replay', 'llr_detector'} <= set(names)
    assert any(isinstance(n, ast.FunctionDef) and n.name == 'generate_launch_description'
               for n in tree.body)


def test_launch_and_config_are_installed_as_data_files():
    setup = (REPO / 'setup.py').read_text()
    assert "glob('launch/*.py')" in setup and "glob('config/*.yaml')" in setup
