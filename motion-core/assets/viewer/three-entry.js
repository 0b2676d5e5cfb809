// Entry of the three.js bundle (three.min.js): all of three.js, its OrbitControls and its
// GLTFLoader (which plays a rig's GLB in the page), as the global `THREE` (build.sh makes it an
// IIFE; viewer.js uses `THREE.OrbitControls` and `THREE.GLTFLoader`).
export * from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
export { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
