// The nine card faces: leaf-like shapes drawn as SVG, in similar pairs so that
// remembering matters (thesis 7.1.3, figure 7.2): ovate / lanceolate, heart /
// round, five-lobed / three-lobed, pinnate with seven / five leaflets, and a fan.
"use strict";
(function () {
  const NS = "http://www.w3.org/2000/svg";
  const C = [  // [fill, vein] per face; pairs share a hue
    ["#3e8e41", "#1f5e24"], ["#5aa04a", "#2c6a25"],
    ["#8d9b2b", "#56611a"], ["#a3ad3a", "#65701f"],
    ["#cf5a2c", "#8a3215"], ["#e0782f", "#9b4a17"],
    ["#2f8572", "#175447"], ["#43967f", "#1f5f50"],
    ["#d9a928", "#8f6c12"],
  ];
  function lobed(n, deep, r0, span) {  // a palmate blade of n pointed lobes over the stem's base
    const pts = [];
    for (let i = 0; i <= 160; i++) {
      const a = -span / 2 + (span * i) / 160;  // 0 = straight up
      const phase = (2 * Math.PI * n * (a + span / 2)) / span;
      const lobe = Math.pow((1 - Math.cos(phase)) / 2, 0.55);
      const r = r0 * (1 - deep + deep * lobe);
      pts.push([50 + r * Math.sin(a), 58 - r * Math.cos(a)]);
    }
    return "M50,62 L" + pts.map(p => p[0].toFixed(1) + "," + p[1].toFixed(1)).join(" L") + " Z";
  }
  function pinnate(pairs) {
    let s = "";
    const top = 14, bottom = 80, step = (bottom - top - 10) / pairs;
    for (let i = 0; i < pairs; i++) {
      const y = top + 12 + i * step;
      const len = 15 + i * 2.2;
      s += `<ellipse cx="${50 - len * 0.72}" cy="${y - 3}" rx="${len * 0.62}" ry="${5.5 + i * 0.4}" transform="rotate(-28 ${50 - len * 0.72} ${y - 3})"/>`;
      s += `<ellipse cx="${50 + len * 0.72}" cy="${y - 3}" rx="${len * 0.62}" ry="${5.5 + i * 0.4}" transform="rotate(28 ${50 + len * 0.72} ${y - 3})"/>`;
    }
    s += `<ellipse cx="50" cy="${top + 3}" rx="6" ry="10"/>`;
    return s;
  }
  const stem = (y0, y1) => `<path d="M50,${y0} L50,${y1}" class="stem"/>`;
  const SHAPES = [
    // 0 ovate, 1 lanceolate
    () => `<path d="M50,8 C84,26 84,66 50,84 C16,66 16,26 50,8 Z"/>` +
          `<g class="vein"><path d="M50,12 L50,84"/><path d="M50,34 L66,26 M50,48 L70,40 M50,62 L66,56 M50,34 L34,26 M50,48 L30,40 M50,62 L34,56"/></g>` + stem(84, 95),
    () => `<path d="M50,6 C68,28 68,64 50,86 C32,64 32,28 50,6 Z"/>` +
          `<g class="vein"><path d="M50,10 L50,86"/><path d="M50,32 L60,26 M50,48 L62,42 M50,64 L60,58 M50,32 L40,26 M50,48 L38,42 M50,64 L40,58"/></g>` + stem(86, 96),
    // 2 heart, 3 round with a notch
    () => `<path d="M50,10 C64,26 92,40 84,62 C78,80 58,80 50,72 C42,80 22,80 16,62 C8,40 36,26 50,10 Z"/>` +
          `<g class="vein"><path d="M50,14 L50,72 M50,40 L70,34 M50,40 L30,34 M50,56 L72,56 M50,56 L28,56"/></g>` + stem(72, 95),
    () => `<path d="M50,14 C76,14 88,34 86,52 C84,72 64,82 54,76 L50,70 L46,76 C36,82 16,72 14,52 C12,34 24,14 50,14 Z"/>` +
          `<g class="vein"><path d="M50,18 L50,70 M50,40 L72,32 M50,40 L28,32 M50,56 L74,58 M50,56 L26,58"/></g>` + stem(70, 95),
    // 4 five-lobed (maple-like), 5 three-lobed
    () => `<path d="${lobed(5, 0.55, 44, 1.5 * Math.PI)}"/>` +
          `<g class="vein"><path d="M50,60 L50,20 M50,60 L20,36 M50,60 L80,36 M50,60 L16,69 M50,60 L84,69"/></g>` + stem(60, 97),
    () => `<path d="${lobed(3, 0.5, 44, 1.3 * Math.PI)}"/>` +
          `<g class="vein"><path d="M50,60 L50,18 M50,60 L18,52 M50,60 L82,52"/></g>` + stem(60, 97),
    // 6 pinnate with seven leaflets, 7 with five
    () => `<g>${pinnate(3)}</g>` + `<path d="M50,14 L50,96" class="stem"/>`,
    () => `<g>${pinnate(2)}</g>` + `<path d="M50,14 L50,96" class="stem"/>`,
    // 8 fan (ginkgo-like)
    () => `<path d="M50,76 L18,30 C30,14 44,12 48,22 L50,30 L52,22 C56,12 70,14 82,30 Z"/>` +
          `<g class="vein"><path d="M50,76 L26,30 M50,76 L36,24 M50,76 L44,22 M50,76 L56,22 M50,76 L64,24 M50,76 L74,30"/></g>` + stem(76, 96),
  ];
  function faceSvg(face) {
    if (!(face >= 0 && face < SHAPES.length)) return "";
    const [fill, vein] = C[face];
    return `<svg xmlns="${NS}" viewBox="0 0 100 100" class="face face-${face}" role="img" aria-label="leaf ${face + 1}">` +
      `<g fill="${fill}" stroke="${vein}" stroke-width="1.6" stroke-linejoin="round">` +
      SHAPES[face]()
        .replaceAll('<g class="vein">', `<g fill="none" stroke="${vein}" stroke-width="1.3" opacity="0.75">`)
        .replaceAll('class="stem"', `fill="none" stroke="${vein}" stroke-width="3" stroke-linecap="round"`) +
      `</g></svg>`;  // presentation attributes, not <style>: the pages' CSP allows no inline styles
  }
  window.pairplayFaces = { faceSvg, count: SHAPES.length };
})();
