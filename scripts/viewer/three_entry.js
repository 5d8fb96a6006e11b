// Entry of the three.js bundle embedded in view.html (see
// build_three_bundle.sh): the parts of three's core that the page uses, plus
// the two add-ons, exposed as one global `THREE` (tree-shaken by esbuild:
// a name the page needs must be listed here).
import {
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
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

globalThis.THREE = {
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
  GLTFLoader,
  OrbitControls,
};
