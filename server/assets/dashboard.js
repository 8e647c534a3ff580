// The tslg dashboard: polls the coordinator's JSON API and redraws. No
// framework and no build step; the figures are SVG drawn by the server.
'use strict';

const params = new URLSearchParams(location.search);
// ?refresh=MS sets the polling period (default 2 s).
const REFRESH = Math.max(100, Number(params.get('refresh')) || 2000);
const page = document.body.dataset.page;
const pageId = document.body.dataset.id;

async function json(url) {
  const response = await fetch(url, { cache: 'no-store' });
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response.json();
}

async function text(url) {
  const response = await fetch(url, { cache: 'no-store' });
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response.text();
}

const fmt = {
  count: (v) => (v == null ? '–' : Number(v).toLocaleString('en-US')),
  sci: (v) => (v == null ? '–' : v === 0 ? '0' : v.toExponential(3)),
  ratio: (v) => (v == null ? '–' : v.toFixed(3)),
  rate: (v) => (v == null ? '–' : v >= 100 ? Math.round(v).toLocaleString('en-US') : v.toFixed(1)),
  seconds(s) {
    if (s == null) return '–';
    if (s < 60) return `${Math.round(s)} s`;
    if (s < 3600) return `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
    if (s < 86400) return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
    return `${(s / 86400).toFixed(1)} d`;
  },
  interval: (c) => (c.ci_low == null ? '–' : `[${fmt.sci(c.ci_low)}, ${fmt.sci(c.ci_high)}]`),
  // The coordinator's name for it: the model or program and the
  // parameters that differ from the model's defaults (`vut_label`).
  vehicle: (v, label) => label || (v.model ?? (v.external ? `external ${v.external}` : JSON.stringify(v))),
};

// Share of the way to β: tests done of those predicted, since the
// relative half-width shrinks as 1/√n.
function progress(c) {
  if (c.status === 'converged') return 1;
  if (!c.predicted_tests) return 0;
  return Math.min(1, c.tests / c.predicted_tests);
}

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') node.className = v;
    else if (k.startsWith('data-')) node.setAttribute(k, v);
    else node[k] = v;
  }
  for (const child of children) node.append(child instanceof Node ? child : String(child));
  return node;
}

function bar(share, done) {
  const inner = el('div');
  inner.style.width = `${(share * 100).toFixed(1)}%`;
  return el('div', { class: done ? 'bar done' : 'bar' }, inner);
}

// A numeric cell that carries its exact value in data-value.
function num(field, value, shown) {
  return el('td', { class: 'num', 'data-field': field, 'data-value': value ?? '' }, shown);
}

function fill(table, rows, empty) {
  const body = document.querySelector(`#${table} tbody`);
  if (rows.length === 0) {
    body.replaceChildren(el('tr', { class: 'empty' }, el('td', { colSpan: 20 }, empty)));
  } else {
    body.replaceChildren(...rows);
  }
}

// A mark on a campaign's status when it has warnings: their number, the
// texts on hover, the campaign page for the full list.
function warningMark(warnings) {
  if (warnings.length === 0) return '';
  return el('span', {
    class: 'warned', title: warnings.join('\n\n'),
    'data-field': 'warnings', 'data-value': warnings.length,
  }, ` ⚠ ${warnings.length}`);
}

// A campaign's line. Its tests are all it used, as the command line and
// its page count them (an adaptive campaign's library, search and
// estimation tests). A library build's surrogate runs estimate no failure
// rate: its line says which library it builds and shows no estimate.
// A warning's text with its `quoted` API fields as code, not backticks.
function prose(text) {
  return text.split('`').map((part, k) => (k % 2 === 1 ? el('code', {}, part) : part));
}

function campaignRow(c) {
  const build = !applies(c).estimate;
  const r = build ? null : c.relative_half_width;
  const halfWidth = el('td', { 'data-field': 'relative_half_width', 'data-value': r ?? '' },
    build ? '–' : bar(progress(c), c.status === 'converged'),
    build ? '' : `${fmt.ratio(r)} → ${c.beta}`);
  const tests = c.adaptive ? c.indices : c.tests;
  const kind = build ? `building library ${c.library_id}`
    : c.adaptive ? `${c.method}, library ${c.library_id}` : `library ${c.library_id}`;
  const estimate = build ? null : c.estimate;
  return el('tr', { id: `campaign-${c.id}`, 'data-status': c.status },
    el('td', {}, el('a', { href: `/campaigns/${c.id}` }, c.id)),
    el('td', {}, c.case),
    el('td', { 'data-field': 'method' }, (c.method_facts.uses_library || build) && c.library_id != null
      ? el('a', { href: `/libraries/${c.library_id}` }, kind)
      : c.method),
    el('td', {}, fmt.vehicle(c.vut, c.vut_label)),
    el('td', { class: `status-${c.status}`, 'data-field': 'status' }, c.status,
      warningMark(c.warnings ?? [])),
    num('tests', tests, fmt.count(tests)),
    num('events', c.events, fmt.count(c.events)),
    num('estimate', estimate, build ? '–' : fmt.sci(estimate)),
    el('td', { 'data-field': 'interval' }, build ? '–'
      : fmt.interval(c) + (c.interval === 'anytime' ? ' (anytime)' : '')),
    halfWidth,
    num('tests_per_second', c.tests_per_second, fmt.rate(c.tests_per_second)),
    num('seconds_left', c.seconds_left, fmt.seconds(c.seconds_left)));
}

function workerRow(w) {
  const share = w.tests > 0 ? w.invalid / w.tests : null;
  const health = w.unhealthy.length === 0
    ? el('td', { 'data-field': 'health' }, w.live ? 'live' : w.left ? 'left' : 'not seen for a minute')
    : el('td', { class: 'unhealthy', title: w.unhealthy.map((u) => `${u.name}: ${u.reason}`).join('\n') },
      `unhealthy: ${w.unhealthy.map((u) => u.name).join(', ')}`);
  return el('tr', { id: `worker-${w.name}` },
    el('td', {}, w.name),
    num('threads', w.threads, w.threads),
    num('last_seen_seconds', w.last_seen_seconds, fmt.seconds(w.last_seen_seconds) + ' ago'),
    num('tests', w.tests, fmt.count(w.tests)),
    num('invalid_share', share, share == null ? '–' : `${(share * 100).toFixed(2)} %`),
    el('td', {}, w.offers.join(', ') || 'built-in vehicles'),
    health);
}

function libraryRow(l) {
  return el('tr', { id: `library-${l.id}` },
    el('td', {}, el('a', { href: `/libraries/${l.id}` }, l.id)),
    el('td', {}, l.case),
    el('td', {}, fmt.vehicle(l.surrogate, l.surrogate_label)),
    el('td', { class: `status-${l.status}` }, l.status),
    num('size', l.size, fmt.count(l.size)),
    num('total_scenarios', l.total_scenarios, fmt.count(l.total_scenarios)),
    num('mu_s', l.mu_s, fmt.sci(l.mu_s)),
    num('build_seconds', l.build_seconds, fmt.seconds(l.build_seconds)));
}

function stamp() {
  document.getElementById('updated').textContent = `updated ${new Date().toLocaleTimeString()}`;
}

function set(id, value, exact) {
  const node = document.getElementById(id);
  node.textContent = value;
  if (exact !== undefined) node.dataset.value = exact ?? '';
}

async function indexPage() {
  const [campaigns, workers, libraries] = await Promise.all([
    json('/api/v1/campaigns'), json('/api/v1/workers'), json('/api/v1/libraries')]);
  fill('campaigns', campaigns.campaigns.map(campaignRow), 'no campaigns yet');
  // Every campaign's warnings in words, above the list: the mark on a
  // status is easy to miss and its hover text unreachable on a touch screen.
  document.getElementById('warnings').replaceChildren(...campaigns.campaigns.flatMap((c) =>
    (c.warnings ?? []).map((w) => el('li', { 'data-campaign': c.id },
      el('a', { href: `/campaigns/${c.id}` }, `campaign ${c.id}`), ': ', ...prose(w)))));
  fill('workers', workers.workers.map(workerRow), 'no workers seen yet');
  fill('libraries', libraries.map(libraryRow), 'no libraries yet');
  return true;
}

// Which of a campaign page's parts (`data-applies`) apply to `c`: a
// library build's surrogate runs estimate nothing; only an adaptive
// campaign (one whose method runs in stages) has stages; only a campaign
// with an outside bound shows it. The page asks the view, never a
// method's name (docs/architecture.md, "Adding a campaign method").
function applies(c) {
  return {
    estimate: c.method_facts.estimates,
    adaptive: c.adaptive != null,
    outside: c.outside_upper != null || c.guarded_ci_high != null,
    answer: c.answer != null,
  };
}

async function campaignPage() {
  const c = await json(`/api/v1/campaigns/${pageId}`);
  const parts = applies(c);
  for (const node of document.querySelectorAll('[data-applies]')) {
    node.hidden = !parts[node.dataset.applies];
  }
  set('verdict', c.verdict ? `Verdict: ${c.verdict}` : '');
  set('status', c.status);
  document.getElementById('status').className = `status-${c.status}`;
  set('tests-label', parts.estimate ? c.method_facts.tests_axis : 'surrogate runs');
  set('tests', fmt.count(c.tests), c.tests);
  set('indices', fmt.count(c.indices), c.indices);
  set('events', fmt.count(c.events), c.events);
  set('invalid', fmt.count(c.invalid), c.invalid);
  set('estimate', fmt.sci(c.estimate), c.estimate);
  set('interval', fmt.interval(c));
  set('interval-kind', c.interval === 'anytime' ? 'anytime interval' : 'interval (Wald)');
  // The interval to report and why (the API's `answer`): the guarded one
  // for a guarded campaign and for a noisy vehicle.
  set('answer', c.answer ? `[${fmt.sci(c.answer.low)}, ${fmt.sci(c.answer.high)}]` : '–',
    c.answer?.high);
  set('answer-reason', c.answer ? `${c.answer.interval}: ${c.answer.reason}` : '');
  set('relative-half-width', fmt.ratio(c.relative_half_width), c.relative_half_width);
  set('beta', c.beta);
  set('rate', fmt.rate(c.tests_per_second), c.tests_per_second);
  set('left', fmt.seconds(c.seconds_left), c.seconds_left);
  const a = c.adaptive;
  const sampling = c.method_facts.splits_by_epsilon ? `, ε ${c.epsilon} (${c.split} split)`
    : a ? `: ${a.library_tests} library and ${a.search_tests} search tests, ${a.stages} stages`
      + (a.running ? `, running a ${a.running.kind} stage` : '') : '';
  const what = parts.estimate ? `${c.case}, ${c.method}${sampling}`
    : `${c.case}, the surrogate runs of library ${c.library_id}'s build`;
  set('detail', c.status_detail ?? `${what}, vehicle ${fmt.vehicle(c.vut, c.vut_label)}, seed ${c.seed}`);
  // The outside bound and the guarded interval exist for library and
  // adaptive campaigns of grid cases (docs/statistics.md): the failure mass
  // the library, or the support K the adaptive campaign found, leaves out.
  set('outside-label', parts.adaptive ? 'outside the support K ≤' : 'outside the library ≤');
  set('outside-upper', fmt.sci(c.outside_upper), c.outside_upper);
  set('guarded-interval', c.guarded_ci_high == null ? '–'
    : `[${fmt.sci(c.ci_low)}, ${fmt.sci(c.guarded_ci_high)}]`, c.guarded_ci_high);
  document.getElementById('warnings').replaceChildren(
    ...(c.warnings ?? []).map((w) => el('li', {}, ...prose(w))));
  await pairSection(c);
  const share = progress(c);
  document.getElementById('progress').style.width = `${(share * 100).toFixed(1)}%`;
  const figures = parts.estimate ? [
    ['estimate-figure', 'estimate.svg'], ['half-width-figure', 'relative-half-width.svg']] : [];
  if (parts.adaptive) {
    adaptiveSection(c);
    figures.push(['stages-figure', 'stages.svg'], ['support-figure', 'support.svg']);
  }
  const drawn = await Promise.all(figures.map(([, name]) =>
    text(`/api/v1/campaigns/${pageId}/figures/${name}`)));
  figures.forEach(([id], k) => { document.getElementById(id).innerHTML = drawn[k]; });
  return !['converged', 'exhausted', 'cancelled', 'failed'].includes(c.status);
}

// An adaptive campaign's stages in numbers: where its tests went.
function adaptiveSection(c) {
  const a = c.adaptive;
  set('library-tests', fmt.count(a.library_tests), a.library_tests);
  set('search-tests', fmt.count(a.search_tests), a.search_tests);
  set('estimation-tests', fmt.count(c.tests), c.tests);
  set('stages', fmt.count(a.stages), a.stages);
  set('support', fmt.count(a.support), a.support);
  set('adaptive-detail', `The library's tests and the searches around the failures and near misses `
    + `they met found where the vehicle fails; only the estimation tests enter the estimate: most are drawn from the support K, `
    + `a share by exposure outside it. Its interval assumes every `
    + `failure is reachable from what the tests met (docs/statistics.md, "Adaptive campaigns").`);
}

// A paired regression campaign: both vehicles' rates over the pair's tests
// and the difference with its paired interval (docs/statistics.md).
async function pairSection(c) {
  const p = c.pair;
  const section = document.getElementById('pair');
  section.hidden = !p;
  if (!p) return;
  const other = p.campaign_a === c.id ? p.campaign_b : p.campaign_a;
  const [b, drawn] = await Promise.all([json(`/api/v1/campaigns/${other}`),
    text(`/api/v1/campaigns/${other}/figures/estimate.svg`)]);
  document.getElementById('pair-figure').innerHTML = drawn;
  const [ca, cb] = p.campaign_a === c.id ? [c, b] : [b, c];
  const [va, vb] = [fmt.vehicle(ca.vut, ca.vut_label), fmt.vehicle(cb.vut, cb.vut_label)];
  set('pair-status', p.stop ? `${p.status} (${p.stop})` : p.status);
  document.getElementById('pair-status').className = `status-${p.status}`;
  const zero = !p.difference ? 'no interval yet'
    : p.difference.ci_low > 0 || p.difference.ci_high < 0
      ? 'its interval excludes zero' : 'its interval holds zero';
  set('pair-detail', `${fmt.count(p.tests)} tests drawn the same for both vehicles, `
    + `${fmt.count(p.discordant)} where only one failed; the difference a − b: ${zero}`
    + (p.look_confidence ? ` (at confidence ${p.look_confidence.toFixed(4)})` : '')
    + (p.independent_tests ? `; two separate campaigns would need about `
      + `${fmt.count(Math.round(p.independent_tests))} tests each for this half-width` : '')
    + (p.exact_difference != null ? `; exact difference ${fmt.sci(p.exact_difference)}` : ''));
  const interval = (i) => (i ? `[${fmt.sci(i.ci_low)}, ${fmt.sci(i.ci_high)}]` : '–');
  const row = (name, id, vehicle, events, rate) => el('tr', { 'data-row': name },
    el('td', {}, name),
    el('td', {}, id == null ? '' : el('a', { href: `/campaigns/${id}` }, `campaign ${id}`)),
    el('td', { 'data-field': 'vehicle' }, vehicle ?? ''),
    events == null ? el('td') : num('events', events, fmt.count(events)),
    num('estimate', rate?.estimate, fmt.sci(rate?.estimate)),
    el('td', { 'data-field': 'interval' }, interval(rate)));
  fill('pair-rates', [
    row('a', p.campaign_a, va, p.events_a, p.rate_a),
    row('b', p.campaign_b, vb, p.events_b, p.rate_b),
    row('a − b', null, null, null, p.difference)], 'no tests yet');
}

async function libraryPage() {
  const l = await json(`/api/v1/libraries/${pageId}`);
  set('case', l.case);
  set('surrogate', fmt.vehicle(l.surrogate, l.surrogate_label));
  set('status', l.status);
  set('size', fmt.count(l.size), l.size);
  set('total', fmt.count(l.total_scenarios), l.total_scenarios);
  set('mu-s', fmt.sci(l.mu_s), l.mu_s);
  set('evaluations', fmt.count(l.sm_evaluations), l.sm_evaluations);
  set('build', l.progress ? `${fmt.count(l.progress.done)} of ${fmt.count(l.progress.total)}` : fmt.seconds(l.build_seconds));
  set('detail', l.error ?? `exposure ${l.exposure}, created ${l.created_at}`);
  if (l.status !== 'ready') return l.status === 'building';
  document.getElementById('picture').innerHTML = await text(`/api/v1/libraries/${pageId}/figures/picture.svg`);
  return false;
}

const pages = { index: indexPage, campaign: campaignPage, library: libraryPage };

async function poll() {
  let again = true;
  try {
    again = await pages[page]();
    stamp();
  } catch (error) {
    document.getElementById('updated').textContent = `update failed: ${error.message}`;
  }
  if (again) setTimeout(poll, REFRESH);
}

poll();
