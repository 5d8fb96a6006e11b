// Loads a run's result files with three.js' own loaders, in node, and prints
// what three.js made of them (one JSON line per file). README's statements
// about three.js are checked with this.
//
//   mkdir /tmp/three && cd /tmp/three && npm init -y && npm install three@0.187.0
//   cp SURFSYNTH/scripts/threejs/check_loaders.mjs . && node check_loaders.mjs RUN_DIR
//
// (ES modules resolve `three` from the script's own folder.) Textures are not decoded (node has no image
// decoder); the MTL check lists each map, the file it names and whether
// that file exists, and the colour space three.js gives it.
import fs from 'node:fs';
import path from 'node:path';
import * as THREE from 'three';
import { OBJLoader } from 'three/examples/jsm/loaders/OBJLoader.js';
import { MTLLoader } from 'three/examples/jsm/loaders/MTLLoader.js';
import { PLYLoader } from 'three/examples/jsm/loaders/PLYLoader.js';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const dir = process.argv[2];
const warnings = [];
for (const level of ['warn', 'error']) {
  const original = console[level];
  console[level] = (...args) => { warnings.push(args.join(' ')); if (level === 'error') original(...args); };
}
// MTLLoader asks its TextureLoader for images; node has none, so record
// the requests instead.
THREE.TextureLoader.prototype.load = function (url, onLoad) {
  const t = new THREE.Texture();
  t.userData.url = url;
  if (onLoad) setTimeout(() => onLoad(t), 0);
  return t;
};
// GLTFLoader looks for a browser global.
globalThis.self = globalThis;

function attributes(geometry) {
  return Object.fromEntries(Object.entries(geometry.attributes).map(([k, a]) => [k, a.count]));
}

for (const name of fs.readdirSync(dir).sort()) {
  const file = path.join(dir, name);
  const out = { file: name };
  try {
    if (name.startsWith('result') && name.endsWith('.obj')) {
      const loader = new OBJLoader();
      const mtlName = name.replace(/\.obj$/, '.mtl');
      if (fs.existsSync(path.join(dir, mtlName))) {
        const materials = new MTLLoader().setResourcePath(dir + '/').parse(fs.readFileSync(path.join(dir, mtlName), 'utf8'), dir + '/');
        materials.preload();
        loader.setMaterials(materials);
        out.maps = {};
        for (const [mname, m] of Object.entries(materials.materials)) {
          for (const key of ['map', 'normalMap', 'roughnessMap', 'bumpMap', 'displacementMap']) {
            if (m[key]) {
              const url = m[key].userData.url;
              out.maps[key] = { file: path.basename(url), exists: fs.existsSync(url), colorSpace: m[key].colorSpace };
            }
          }
        }
      }
      const group = loader.parse(fs.readFileSync(file, 'utf8'));
      out.meshes = group.children.map((c) => attributes(c.geometry));
    } else if (name.startsWith('result') && name.endsWith('.ply')) {
      const g = new PLYLoader().parse(fs.readFileSync(file).buffer);
      out.attributes = attributes(g);
    } else if (name.endsWith('.glb')) {
      const bytes = fs.readFileSync(file);
      const gltf = await new Promise((resolve, reject) =>
        new GLTFLoader().parse(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.length), dir + '/', resolve, reject));
      out.meshes = [];
      gltf.scene.traverse((o) => {
        if (o.isMesh) {
          const m = o.material;
          out.meshes.push({
            attributes: attributes(o.geometry),
            map: !!m.map, normalMap: !!m.normalMap, metalnessMap: !!m.metalnessMap, roughnessMap: !!m.roughnessMap,
          });
        }
      });
    } else {
      continue;
    }
  } catch (e) {
    out.error = String(e);
  }
  console.log(JSON.stringify(out));
}
if (warnings.length) console.log(JSON.stringify({ warnings }));
