"""A web page in a real browser against the bridge's ports (headless Chromium, Debian's).

Issue 36: on main 91ca172 any page open on the operator's machine could read the live
telemetry: the front accepted every Origin on a loopback host, and the SDK's own loopback
port accepted ``Origin: https://evil.example``. A page served as ``http://evil.example``
(mapped to 127.0.0.1 by Chromium's resolver rules) now reaches neither; the same page
served as ``http://localhost`` connects to the front and still not to the SDK's port.
"""

import http.server
import json
import pathlib
import queue
import shutil
import subprocess
import threading
import urllib.parse

import pytest

CHROMIUM = shutil.which('chromium')
PAGE = '''<html><body><script>
const targets = %s;
function attempt(url) {
  return new Promise((done) => {
    let ws;
    try { ws = new WebSocket(url, ['foxglove.sdk.v1']); } catch (e) { done('refused'); return; }
    const timer = setTimeout(() => done('timeout'), 10000);
    ws.onopen = () => { clearTimeout(timer); ws.close(); done('open'); };
    ws.onerror = () => { clearTimeout(timer); done('refused'); };
  });
}
(async () => {
  const out = {};
  for (const [name, url] of Object.entries(targets)) out[name] = await attempt(url);
  await fetch('/report?' + encodeURIComponent(JSON.stringify(out)));
})();
</script></body></html>'''


@pytest.fixture
def bridge_ports():
    """Yield (front, SDK port), set up as the bridge does (TLS upstream, default origins)."""
    foxglove = pytest.importorskip('foxglove')
    from rwa_monitor.nodes.foxglove_front import loopback_certificate, trusting, WebSocketFront
    certificate, key = loopback_certificate()
    context = foxglove.Context()
    foxglove.Channel('/x', schema={'type': 'object'}, context=context)
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context,
                                   tls_cert=certificate, tls_key=key)
    gate = WebSocketFront('127.0.0.1', 0, server.port, [], lambda text: None,
                          upstream_tls=trusting(certificate))
    try:
        yield gate, server.port
    finally:
        gate.stop()
        server.stop()


def _visit(host: str, targets: dict, profile: pathlib.Path) -> dict:
    """Serve PAGE, open it as ``http://HOST:PORT`` in Chromium, return what it reported."""
    reports: queue.Queue = queue.Queue()

    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self):   # noqa: N802 - the name http.server calls
            if self.path.startswith('/report?'):
                reports.put(json.loads(urllib.parse.unquote(self.path[len('/report?'):])))
                body = b'ok'
            else:
                body = (PAGE % json.dumps(targets)).encode()
            self.send_response(200)
            self.send_header('Content-Type', 'text/html')
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    site = http.server.ThreadingHTTPServer(('127.0.0.1', 0), Page)
    threading.Thread(target=site.serve_forever, daemon=True).start()
    browser = subprocess.Popen(
        [CHROMIUM, '--headless=new', '--no-sandbox', '--disable-gpu',
         '--host-resolver-rules=MAP evil.example 127.0.0.1', f'--user-data-dir={profile}',
         f'http://{host}:{site.server_address[1]}/page.html'],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        return reports.get(timeout=90)
    finally:
        browser.kill()
        browser.wait()
        site.shutdown()


@pytest.mark.skipif(CHROMIUM is None, reason='chromium is not installed (apt-get install '
                    'chromium)')
def test_a_foreign_page_reaches_no_port_and_a_local_page_only_the_front(bridge_ports,
                                                                        tmp_path):
    gate, sdk = bridge_ports
    targets = {'front': f'ws://127.0.0.1:{gate.port}', 'sdk': f'ws://127.0.0.1:{sdk}',
               'sdk_tls': f'wss://127.0.0.1:{sdk}'}
    foreign = _visit('evil.example', targets, tmp_path / 'a')
    assert foreign == {'front': 'refused', 'sdk': 'refused', 'sdk_tls': 'refused'}
    assert gate.refused == 1
    local = _visit('localhost', targets, tmp_path / 'b')
    assert local == {'front': 'open', 'sdk': 'refused', 'sdk_tls': 'refused'}
