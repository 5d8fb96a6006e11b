// Entry of the three.js bundle embedded in view.html (see
// build_three_bundle.sh, which makes these exports the global `THREE`):
// the parts of three's core that the page uses, plus the two add-ons
// (tree-shaken by esbuild: a name the page needs must be listed here).
export {
  Box3,
  Color,
  DirectionalLight,
  DoubleSide,
  HemisphereLight,
  MathUtils,
  PerspectiveCamera,
  REVISION,
  SRGBColorSpace,
  Scene,
  Vector3,
  WebGLRenderer,
} from "three";
export { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
export { OrbitControls } from "three/addons/controls/OrbitControls.js";
