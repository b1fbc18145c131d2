// Start Open MCT with the rwa_monitor plugin (served by `rwa-monitor openmct`).
/* global openmct, RwaMonitor */
(function () {
  'use strict';
  openmct.setAssetPath('/openmct/');
  RwaMonitor.fetchDictionary().then((dictionary) => {
    openmct.install(openmct.plugins.Espresso());
    openmct.install(openmct.plugins.UTCTimeSystem());
    openmct.install(openmct.plugins.DisplayLayout({ showAsView: [] }));
    openmct.install(openmct.plugins.LADTable());
    openmct.install(RwaMonitor.plugin(dictionary));
    openmct.install(openmct.plugins.Conductor({ menuOptions: RwaMonitor.conductor(dictionary) }));
    if (!window.location.hash || window.location.hash === '#/') {
      window.location.hash = RwaMonitor.defaultPath();
    }
    openmct.start();
  }).catch((error) => {
    document.getElementById('app').textContent =
      'rwa_monitor: cannot read /api/dictionary from the server: ' + error;
  });
})();
