// Entry of the three.js bundle (three.min.js): all of three.js and its OrbitControls, as the
// global `THREE` (build.sh makes it an IIFE; viewer.js uses `THREE.OrbitControls`).
export * from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
