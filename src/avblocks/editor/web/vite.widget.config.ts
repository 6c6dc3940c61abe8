import { defineConfig } from 'vite';
import react from '@vitejs/plugin-react';

// The anywidget module: one self-contained static/widget.js (CSS inlined), built after the page.
export default defineConfig({
  plugins: [react()],
  define: { 'process.env.NODE_ENV': '"production"' },
  build: {
    outDir: '../static',
    emptyOutDir: false,
    sourcemap: false,
    chunkSizeWarningLimit: 4000,
    lib: { entry: 'src/widget.tsx', formats: ['es'], fileName: () => 'widget.js' },
    // a library build in 'es' format keeps its whitespace unless the output asks: the widget is
    // loaded as it is (never bundled again), so it is minified like the page
    minify: true,
    rollupOptions: { output: { codeSplitting: false, minify: true } },
  },
});
