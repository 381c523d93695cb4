// The error curve (the paper's fig. 7): mean E over the motion against kept joints, one
// line per variant, the unoptimised baseline dashed, the chosen level marked.
import { kLevelColours } from './crowd.js';

const NS = 'http://www.w3.org/2000/svg';

function element(name, attributes, text) {
  const node = document.createElementNS(NS, name);
  for (const [key, value] of Object.entries(attributes)) node.setAttribute(key, value);
  if (text !== undefined) node.textContent = text;
  return node;
}

function niceStep(range, ticks) {
  const raw = range / ticks;
  const power = 10 ** Math.floor(Math.log10(raw));
  const scaled = raw / power;
  return (scaled <= 1 ? 1 : scaled <= 2 ? 2 : scaled <= 5 ? 5 : 10) * power;
}

// `series`: [{ label, colour (an index), points: [{ joints, value }], dashed }];
// `marker`: kept joints of the chosen level (or null).
export function drawCurves(svg, series, marker) {
  svg.replaceChildren();
  const width = Number(svg.getAttribute('width'));
  const height = Number(svg.getAttribute('height'));
  const margin = { left: 56, right: 170, top: 12, bottom: 36 };
  const points = series.flatMap((s) => s.points);
  if (points.length === 0) return;
  const xs = points.map((p) => p.joints);
  const xMin = Math.min(...xs);
  const xMax = Math.max(...xs, xMin + 1);
  const yMax = Math.max(...points.map((p) => p.value)) || 1;
  const x = (joints) => margin.left + ((xMax - joints) / (xMax - xMin)) * (width - margin.left - margin.right);
  const y = (value) => height - margin.bottom - (value / yMax) * (height - margin.top - margin.bottom);

  const yStep = niceStep(yMax, 5);
  for (let value = 0; value <= yMax * 1.0001; value += yStep) {
    svg.append(element('line', { x1: margin.left, x2: width - margin.right, y1: y(value), y2: y(value), stroke: '#e3e6ec' }));
    svg.append(element('text', { x: margin.left - 6, y: y(value) + 4, 'text-anchor': 'end' }, value.toPrecision(2)));
  }
  const xStep = Math.max(1, Math.round(niceStep(xMax - xMin, 8)));
  for (let joints = xMax; joints >= xMin; joints -= xStep) {
    svg.append(element('text', { x: x(joints), y: height - margin.bottom + 16, 'text-anchor': 'middle' }, String(joints)));
  }
  svg.append(element('text', { x: (margin.left + width - margin.right) / 2, y: height - 4, 'text-anchor': 'middle' }, 'kept joints'));
  svg.append(element('text', { x: 12, y: margin.top + 10, transform: `rotate(-90 12 ${margin.top + 10})`, 'text-anchor': 'end' }, 'mean E'));
  if (marker !== null) {
    svg.append(element('line', { x1: x(marker), x2: x(marker), y1: margin.top, y2: height - margin.bottom, stroke: '#9aa1ae', 'stroke-dasharray': '2 3' }));
  }

  series.forEach((s, k) => {
    const colour = kLevelColours[s.colour % kLevelColours.length];
    const sorted = [...s.points].sort((a, b) => b.joints - a.joints);
    const path = sorted.map((p, i) => `${i ? 'L' : 'M'}${x(p.joints).toFixed(1)},${y(p.value).toFixed(1)}`).join(' ');
    svg.append(element('path', { d: path, fill: 'none', stroke: colour, 'stroke-width': 2, 'stroke-dasharray': s.dashed ? '5 4' : 'none', 'data-series': s.label }));
    for (const p of sorted) {
      svg.append(element('circle', { cx: x(p.joints), cy: y(p.value), r: 3, fill: colour }));
    }
    const legendY = margin.top + 14 + k * 16;
    svg.append(element('line', { x1: width - margin.right + 10, x2: width - margin.right + 30, y1: legendY - 4, y2: legendY - 4, stroke: colour, 'stroke-width': 2, 'stroke-dasharray': s.dashed ? '5 4' : 'none' }));
    svg.append(element('text', { x: width - margin.right + 34, y: legendY }, s.label));
  });
}
